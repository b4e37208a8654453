/* pagecache — a file's pages in the page cache, for tests and benchmarks of the disk tier:
 * how many are resident (mincore over a read-only mapping) and dropping them
 * (posix_fadvise DONTNEED: clean pages no process maps; a file system that keeps its pages,
 * tmpfs, keeps them).
 */
#ifndef CLIPMAP_TEST_PAGECACHE_H
#define CLIPMAP_TEST_PAGECACHE_H
#include <stddef.h>

/* Resident pages of the file at path in *resident and its pages in *total; 0 or -errno. */
int pagecache_count(const char *path, size_t *resident, size_t *total);
/* Drops the file's clean, unmapped pages from the page cache; 0 or -errno. */
int pagecache_drop(const char *path);
/* Reads the file through once (its pages in the page cache, as memory allows); 0 or -errno. */
int pagecache_fill(const char *path);

#endif
