/* planet_variant — see planet_variant.h. */
#include "planet_variant.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The directory of src, as an absolute path when it resolves. */
static void src_dir(const char *src, char *dir, size_t size)
{
	char abs[PATH_MAX];
	const char *s = realpath(src, abs) ? abs : src;
	const char *slash = strrchr(s, '/');
	if (!slash)
		snprintf(dir, size, ".");
	else
		snprintf(dir, size, "%.*s", (int)(slash - s), s);
}

int planet_variant_write(const char *src, const char *tag, char *fp_path, char *direct_path,
			 size_t size)
{
	FILE *in = fopen(src, "r");
	if (!in)
		return -1;
	snprintf(fp_path, size, "/tmp/%s_%d.ini", tag, (int)getpid());
	snprintf(direct_path, size, "/tmp/%s_d%d.ini", tag, (int)getpid());
	FILE *fp = fopen(fp_path, "w"), *fd = fopen(direct_path, "w");
	if (!fp || !fd) {
		fclose(in);
		if (fp)
			fclose(fp);
		if (fd)
			fclose(fd);
		return -1;
	}
	char line[4096], dir[PATH_MAX];
	src_dir(src, dir, sizeof dir);
	int n = 0;
	while (fgets(line, sizeof line, in)) {
		if (strncmp(line, "from_parent", 11) == 0)
			continue;
		if (strncmp(line, "path = ", 7) == 0 && line[7] != '/') {
			/* a data file beside the planet: by its full path */
			fprintf(fp, "path = %s/%s", dir, line + 7);
			fprintf(fd, "path = %s/%s", dir, line + 7);
			continue;
		}
		fputs(line, fp);
		fputs(line, fd);
		if (strncmp(line, "kind = fbm", 10) == 0) {
			fputs("from_parent = true\n", fp);
			n++;
		}
	}
	fclose(in);
	int werr = ferror(fp) | ferror(fd);
	werr |= fclose(fp) | fclose(fd);
	return n > 0 && !werr ? 0 : -1;
}
