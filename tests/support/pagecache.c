/* pagecache — see pagecache.h. */
#include "support/pagecache.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

int pagecache_count(const char *path, size_t *resident, size_t *total)
{
	*resident = *total = 0;
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0)
		return -errno;
	struct stat st;
	if (fstat(fd, &st)) {
		int e = -errno;
		close(fd);
		return e;
	}
	if (st.st_size == 0) {
		close(fd);
		return 0;
	}
	size_t len = (size_t)st.st_size, pg = (size_t)sysconf(_SC_PAGESIZE);
	size_t np = (len + pg - 1) / pg;
	void *m = mmap(NULL, len, PROT_READ, MAP_SHARED, fd, 0);
	int e = m == MAP_FAILED ? -errno : 0;
	close(fd);
	if (e)
		return e;
	unsigned char *v = malloc(np);
	if (!v)
		e = -ENOMEM;
	else if (mincore(m, len, v))
		e = -errno;
	for (size_t i = 0; !e && i < np; i++)
		*resident += v[i] & 1;
	if (!e)
		*total = np;
	free(v);
	munmap(m, len);
	return e;
}

int pagecache_fill(const char *path)
{
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0)
		return -errno;
	static char buf[1 << 20];
	ssize_t n;
	while ((n = read(fd, buf, sizeof buf)) > 0)
		;
	int e = n < 0 ? -errno : 0;
	close(fd);
	return e;
}

int pagecache_drop(const char *path)
{
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0)
		return -errno;
	int e = -posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
	close(fd);
	return e;
}
