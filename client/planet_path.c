/* planet_path — see planet_path.h. */
#include "planet_path.h"

#include <errno.h>
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int exists(const char *p)
{
	return access(p, R_OK) == 0;
}

int planet_path_resolve(const char *arg, char *out, size_t n)
{
	size_t len = strlen(arg);
	if (strchr(arg, '/') || (len > 4 && strcmp(arg + len - 4, ".ini") == 0)) {
		snprintf(out, n, "%s", arg);
		return exists(out) ? 0 : -ENOENT;
	}
	char first[4096] = "";
	const char *env = getenv("CLIPMAP_PLANETS");
	char exe[4096];
	ssize_t el = readlink("/proc/self/exe", exe, sizeof exe - 1);
	char exedir[4096] = "";
	if (el > 0) {
		exe[el] = '\0';
		snprintf(exedir, sizeof exedir, "%s/../conf/planets", dirname(exe));
	}
	/* the last: where `make install` puts the shipped planets (clipmapd's default) */
	const char *dirs[] = { env, "conf/planets", exedir[0] ? exedir : NULL,
			       "/etc/clipmap/planets" };
	for (size_t i = 0; i < sizeof dirs / sizeof dirs[0]; i++) {
		if (!dirs[i] || !dirs[i][0])
			continue;
		snprintf(out, n, "%s/%s.ini", dirs[i], arg);
		if (!first[0])
			snprintf(first, sizeof first, "%s", out);
		if (exists(out))
			return 0;
	}
	snprintf(out, n, "%s", first[0] ? first : arg);
	return -ENOENT;
}
