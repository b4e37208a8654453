/* file_digest — what identifies a data file's content for the `file` node's content hash: an
 * XXH3-128 digest of its bytes, so identical copies of a dataset on two machines (other paths,
 * inodes, mtimes) name the same tiles fleet-wide, and any changed byte names new ones.
 *
 * Hashing reads the whole file (a few GB/s from the page cache); for files of at least
 * `cache_min` bytes the digest is kept beside the file in FILE.digest, one line
 *     clipmap-digest 1 SIZE MTIME_S MTIME_NS INODE HEX32
 * and reused while size, mtime and inode still match (else recomputed and rewritten). Writing it
 * is best effort (atomic: a temporary file renamed; a read-only directory just means the
 * digest is computed at each load). Smaller files are hashed at every load, leaving their
 * directory untouched.
 * Threads: reentrant. */
#ifndef CLIPMAP_FILE_DIGEST_H
#define CLIPMAP_FILE_DIGEST_H
#include <stdint.h>
#include <sys/stat.h>

/* Files from this size on keep their digest beside them. */
#define FILE_DIGEST_CACHE_MIN ((uint64_t)64 << 20)

/* The digest of path (st: its stat, taken by the caller) into out. Returns 0, or -errno with
 * err filled (unreadable, or the file kept changing while it was read). */
int file_digest(const char *path, const struct stat *st, uint64_t cache_min, uint8_t out[16],
		char err[256]);

#endif
