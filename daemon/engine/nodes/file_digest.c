/* file_digest — see file_digest.h. */
#include "file_digest.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#define XXH_STATIC_LINKING_ONLY /* XXH3_state_t on the stack */
#include <xxhash.h>

#include "common/xalloc.h"

#define CHUNK (1u << 20)

static bool same_file(const struct stat *a, const struct stat *b)
{
	return a->st_size == b->st_size && a->st_mtim.tv_sec == b->st_mtim.tv_sec &&
	       a->st_mtim.tv_nsec == b->st_mtim.tv_nsec && a->st_ino == b->st_ino &&
	       a->st_dev == b->st_dev;
}

/* Reads the sidecar: 0 when it matches st (out filled), else -1. */
static int sidecar_read(const char *side, const struct stat *st, uint8_t out[16])
{
	FILE *f = fopen(side, "r");
	if (!f)
		return -1;
	char line[256];
	bool ok = fgets(line, sizeof line, f) != NULL;
	fclose(f);
	uint64_t size, ino;
	int64_t sec, nsec;
	char hex[33];
	if (!ok || sscanf(line, "clipmap-digest 1 %" SCNu64 " %" SCNd64 " %" SCNd64 " %" SCNu64
			  " %32[0-9a-f]", &size, &sec, &nsec, &ino, hex) != 5 || strlen(hex) != 32)
		return -1;
	if (size != (uint64_t)st->st_size || sec != (int64_t)st->st_mtim.tv_sec ||
	    nsec != (int64_t)st->st_mtim.tv_nsec || ino != (uint64_t)st->st_ino)
		return -1;
	for (int i = 0; i < 16; i++) {
		unsigned v;
		if (sscanf(hex + 2 * i, "%2x", &v) != 1)
			return -1;
		out[i] = (uint8_t)v;
	}
	return 0;
}

static void sidecar_write(const char *side, const struct stat *st, const uint8_t d[16])
{
	char tmp[4200];
	snprintf(tmp, sizeof tmp, "%s.%ld.tmp", side, (long)getpid());
	FILE *f = fopen(tmp, "w");
	if (!f)
		return; /* read-only directory: computed at each load */
	fprintf(f, "clipmap-digest 1 %" PRIu64 " %" PRId64 " %" PRId64 " %" PRIu64 " ",
		(uint64_t)st->st_size, (int64_t)st->st_mtim.tv_sec, (int64_t)st->st_mtim.tv_nsec,
		(uint64_t)st->st_ino);
	for (int i = 0; i < 16; i++)
		fprintf(f, "%02x", d[i]);
	fputc('\n', f);
	if (fclose(f) != 0 || rename(tmp, side) != 0)
		unlink(tmp);
}

/* Hashes the open file; 0, or -errno. *after: its stat once read. */
static int hash_fd(int fd, uint8_t out[16], struct stat *after)
{
	XXH3_state_t s;
	XXH3_128bits_reset(&s);
	uint8_t *buf = xmalloc(CHUNK);
	int rc = 0;
	for (;;) {
		ssize_t n = read(fd, buf, CHUNK);
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0) {
			rc = -errno;
			break;
		}
		if (n == 0)
			break;
		XXH3_128bits_update(&s, buf, (size_t)n);
	}
	free(buf);
	if (rc == 0 && fstat(fd, after) != 0)
		rc = -errno;
	XXH128_canonical_t c;
	XXH128_canonicalFromHash(&c, XXH3_128bits_digest(&s));
	memcpy(out, c.digest, 16);
	return rc;
}

int file_digest(const char *path, const struct stat *st, uint64_t cache_min, uint8_t out[16],
		char err[256])
{
	bool cached = (uint64_t)st->st_size >= cache_min;
	char side[4100];
	snprintf(side, sizeof side, "%s.digest", path);
	if (cached && sidecar_read(side, st, out) == 0)
		return 0;
	struct stat before = *st;
	for (int attempt = 0; attempt < 3; attempt++) {
		int fd = open(path, O_RDONLY | O_CLOEXEC);
		if (fd < 0) {
			int rc = -errno;
			snprintf(err, 256, "cannot read %s: %s", path, strerror(errno));
			return rc;
		}
		struct stat after;
		int rc = hash_fd(fd, out, &after);
		close(fd);
		if (rc) {
			snprintf(err, 256, "cannot read %s: %s", path, strerror(-rc));
			return rc;
		}
		if (same_file(&before, &after)) {
			if (cached)
				sidecar_write(side, &after, out);
			return 0;
		}
		before = after; /* it changed while read: again */
	}
	snprintf(err, 256, "%s keeps changing while it is read", path);
	return -EAGAIN;
}
