/* clipmapctl against a real clipmapd: the daemon runs as a process on a temporary Unix socket
 * with a temporary config and planets directory (the procedural planet: no data files), and
 * clipmapctl runs as real processes. Checks what an operator sees: exit codes, that `tile`
 * writes the same picture `render` makes offline (decoded pixels, exactly), that `cache ls`
 * lists the tile afterwards, that a small prefetch completes with done == total, that status
 * reports, and that a bad socket path is exit 1 with the hint.
 * Skipped when build/clipmapd or build/clipmapctl was not built. */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "common/clipmap.h"
#include "common/img.h"
#include "support/daemon_env.h"

struct env {
	struct daemon_env d;
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	return e ? daemon_env_setup(&e->d, "test_ctl_online", "clipmapctl") : -1;
}

static int teardown(void **state)
{
	struct env *e = *state;
	daemon_env_teardown(&e->d);
	free(e);
	return 0;
}

/* Runs clipmapctl with -s SOCKET and the given arguments. */
static int ctl(struct env *e, char *out, size_t n, const char *a0, ...)
{
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->d.bindir);
	char *argv[32] = { exe, "-s", e->d.sock };
	int argc = 3;
	va_list ap;
	va_start(ap, a0);
	for (const char *a = a0; a && argc < 31; a = va_arg(ap, const char *))
		argv[argc++] = (char *)a;
	va_end(ap);
	argv[argc] = NULL;
	return daemon_env_run(argv, out, n);
}

/* Offline render of the same planet file the daemon serves. */
static int render(struct env *e, char *out, size_t n, const char *layer, const char *path)
{
	char exe[600], planet[300];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->d.bindir);
	snprintf(planet, sizeof planet, "%s/procedural.ini", e->d.planets);
	char *argv[] = { exe, "render", planet, (char *)layer, "2", "1", "3", "0", "-o",
			 (char *)path, "--quiet", NULL };
	return daemon_env_run(argv, out, n);
}

#define NEED_DAEMON(e)                 \
	do {                           \
		if ((e)->d.daemon <= 0)\
			skip();        \
	} while (0)

static void same_pixels(const char *a, const char *b, enum img_type t)
{
	void *pa, *pb;
	struct img_info ia, ib;
	char err[256];
	assert_int_equal(img_read(a, t, &pa, &ia, err), 0);
	assert_int_equal(img_read(b, t, &pb, &ib, err), 0);
	assert_int_equal(ia.width, ib.width);
	assert_int_equal(ia.height, ib.height);
	assert_int_equal(ia.channels, ib.channels);
	assert_memory_equal(pa, pb, (size_t)ia.width * ia.height * ia.channels * img_type_bytes(t));
	free(pa);
	free(pb);
}

/* Whether the `cache ls` table has a row for (layer, lx/ly, x, y); layer NULL: any. */
static bool has_row(const char *out, const char *layer, const char *level, unsigned x,
		    unsigned y)
{
	for (const char *l = out; l && *l; l = strchr(l, '\n') ? strchr(l, '\n') + 1 : NULL) {
		char name[64], lv[16];
		unsigned rx, ry;
		if (sscanf(l, "%63s %15s %u %u", name, lv, &rx, &ry) == 4 &&
		    (!layer || strcmp(name, layer) == 0) && strcmp(lv, level) == 0 && rx == x &&
		    ry == y)
			return true;
	}
	return false;
}

/* The age column of that row, as printed ("" when there is no such row). */
static void row_age(const char *out, const char *layer, const char *level, unsigned x,
		    unsigned y, char age[32])
{
	age[0] = 0;
	for (const char *l = out; l && *l; l = strchr(l, '\n') ? strchr(l, '\n') + 1 : NULL) {
		char name[64], lv[16];
		unsigned rx, ry, bytes;
		if (sscanf(l, "%63s %15s %u %u %u %31s", name, lv, &rx, &ry, &bytes, age) == 6 &&
		    strcmp(name, layer) == 0 && strcmp(lv, level) == 0 && rx == x && ry == y)
			return;
	}
	age[0] = 0;
}

static void tile_equals_render_and_is_listed(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	/* cache ls lists the tiles of every node of the graph: room for a big one */
	char out[65536], a[200], b[200];
	static const struct { const char *layer, *ext; enum img_type t; } cases[] = {
		{ "height", "tif", IMG_F32 }, { "color", "png", IMG_U8 }, { "normal", "png", IMG_U8 },
	};
	for (size_t i = 0; i < 3; i++) {
		snprintf(a, sizeof a, "%s/online_%s.%s", e->d.dir, cases[i].layer, cases[i].ext);
		snprintf(b, sizeof b, "%s/offline_%s.%s", e->d.dir, cases[i].layer, cases[i].ext);
		int rc = ctl(e, out, sizeof out, "tile", "procedural", cases[i].layer, "2", "1", "3",
			     "0", "-o", a, NULL);
		if (rc)
			fprintf(stderr, "%s", out);
		assert_int_equal(rc, 0);
		rc = render(e, out, sizeof out, cases[i].layer, b);
		if (rc)
			fprintf(stderr, "%s", out);
		assert_int_equal(rc, 0);
		same_pixels(a, b, cases[i].t);
	}
	int rc = ctl(e, out, sizeof out, "cache", "ls", "procedural", NULL);
	assert_int_equal(rc, 0);
	assert_true(has_row(out, "height", "2/1", 3, 0));
	assert_true(has_row(out, "color", "2/1", 3, 0));
	assert_true(has_row(out, "normal", "2/1", 3, 0));
	/* the age column: seconds since the tile's last use (just used: a few at most) */
	char age[32];
	double secs = 99;
	row_age(out, "height", "2/1", 3, 0, age);
	assert_true(sscanf(age, "%lfs", &secs) == 1 && secs >= 0 && secs < 10);
	/* the level filter keeps it (ly 1 = level 1), another level does not */
	rc = ctl(e, out, sizeof out, "cache", "ls", "procedural", "--level", "1", "--json", NULL);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "\"layer\": \"height\""));
	assert_non_null(strstr(out, "\"lx\": 2, \"ly\": 1, \"x\": 3, \"y\": 0"));
	rc = ctl(e, out, sizeof out, "cache", "ls", "procedural", "--level", "5", "--json", NULL);
	assert_int_equal(rc, 0);
	assert_null(strstr(out, "\"lx\": 2, \"ly\": 1"));
	/* near the tile's area (lon 90..180, lat 0..90) it is listed; on the far side not */
	rc = ctl(e, out, sizeof out, "cache", "ls", "procedural", "--near", "45,110", NULL);
	assert_int_equal(rc, 0);
	assert_true(has_row(out, "height", "2/1", 3, 0));
	rc = ctl(e, out, sizeof out, "cache", "ls", "procedural", "--near", "-45,-70", NULL);
	assert_int_equal(rc, 0);
	assert_false(has_row(out, NULL, "2/1", 3, 0));
	/* status counts what happened */
	rc = ctl(e, out, sizeof out, "status", NULL);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "hit ratio"));
	assert_non_null(strstr(out, "procedural."));
	rc = ctl(e, out, sizeof out, "status", "--json", NULL);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "\"cache.hit_ratio\": "));
	/* unknown planet and layer: usage errors with the daemon's word */
	rc = ctl(e, out, sizeof out, "tile", "pluto", "height", "0", "0", "0", "0", "-o", a, NULL);
	assert_int_equal(rc, 2);
	assert_non_null(strstr(out, "not-found"));
	rc = ctl(e, out, sizeof out, "tile", "procedural", "lava", "0", "0", "0", "0", "-o", a,
		 NULL);
	assert_int_equal(rc, 2);
	assert_non_null(strstr(out, "no layer \"lava\""));
}

static void prefetch_completes(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char out[16384];
	/* levels 0-1: with their intermediate nodes (~15 a tile) they fit the test daemon's
	 * 64 MiB cache, which deeper levels would overflow (prefetch warms memory only) */
	int rc = ctl(e, out, sizeof out, "prefetch", "procedural", "--bbox", "5,40,15,50",
		     "--levels", "0-1", "--layers", "height", NULL);
	if (rc)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	const char *sum = strstr(out, "prefetch procedural: ");
	assert_non_null(sum);
	unsigned long long done = 0, total = 0;
	assert_int_equal(sscanf(sum, "prefetch procedural: %llu of %llu tiles", &done, &total), 2);
	assert_true(total > 0);
	assert_int_equal(done, total);
	/* the level-1 tile under the box's centre, on the lx a viewer there uses, is cached now */
	int lx = clipmap_level_lx(1, 45, -1);
	char want[128];
	snprintf(want, sizeof want, "\"lx\": %d, \"ly\": 1, \"x\": %d, \"y\": 0", lx,
		 (int)floor((10.0 + 180.0) / 360.0 * (1 << lx)));
	rc = ctl(e, out, sizeof out, "cache", "ls", "procedural", "--level", "1", "--near",
		 "45,10", "--radius", "1", "--json", NULL);
	assert_int_equal(rc, 0);
	if (!strstr(out, want))
		fail_msg("%s not listed:\n%s", want, out);

	/* (one layer: all three, ~76 MiB, would not fit the memory cache and are refused) */
	rc = ctl(e, out, sizeof out, "prefetch", "procedural", "--path", "45,5:47,9", "--width",
		 "10", "--levels", "2-4", "--layers", "height", NULL);
	if (rc)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	sum = strstr(out, "prefetch procedural: ");
	assert_non_null(sum);
	assert_int_equal(sscanf(sum, "prefetch procedural: %llu of %llu tiles", &done, &total), 2);
	assert_int_equal(done, total);
}

/* --dry-run prints the estimate per level and the tier's budget and runs nothing; a job over
 * that budget (here the 64 MiB memory cache: no store) is refused with the same estimate. */
static void prefetch_dry_run(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char out[16384];
	int rc = ctl(e, out, sizeof out, "prefetch", "procedural", "--bbox", "5,40,15,50",
		     "--levels", "3-7", "--dry-run", NULL);
	printf("%s", out);
	assert_int_equal(rc, 0);
	for (int l = 3; l <= 7; l++) {
		char row[16];
		snprintf(row, sizeof row, "\n%-6d ", l);
		assert_non_null(strstr(out, row));
	}
	assert_non_null(strstr(out, "memory tier: budget 64.0 MiB"));
	assert_non_null(strstr(out, "would be refused: larger than the memory tier's budget"));
	const char *tot = strstr(out, "\ntotal ");
	assert_non_null(tot);
	unsigned long long tiles = 0;
	assert_int_equal(sscanf(tot, "\ntotal %llu", &tiles), 1);
	rc = ctl(e, out, sizeof out, "prefetch", "procedural", "--bbox", "5,40,15,50", "--levels",
		 "3-7", "--dry-run", "--json", NULL);
	assert_int_equal(rc, 0);
	char want[64];
	snprintf(want, sizeof want, "\"tiles\": %llu,", tiles);
	assert_non_null(strstr(out, want));
	assert_non_null(strstr(out, "\"tier\": \"memory\""));
	assert_non_null(strstr(out, "\"fits\": false"));
	assert_non_null(strstr(out, "{\"level\": 7, \"tiles\": "));
	/* run: refused with that estimate, nothing generated */
	rc = ctl(e, out, sizeof out, "prefetch", "procedural", "--bbox", "5,40,15,50", "--levels",
		 "3-7", NULL);
	printf("%s", out);
	assert_int_equal(rc, 1);
	snprintf(want, sizeof want, "about %llu tiles", tiles);
	assert_non_null(strstr(out, want));
	assert_non_null(strstr(out, "[engine] cache_mb"));
	/* a small one fits */
	rc = ctl(e, out, sizeof out, "prefetch", "procedural", "--bbox", "5,40,15,50", "--levels",
		 "0-1", "--layers", "height", "--dry-run", NULL);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "would run"));
	/* --json alone is a usage error */
	rc = ctl(e, out, sizeof out, "prefetch", "procedural", "--bbox", "5,40,15,50", "--levels",
		 "0-1", "--json", NULL);
	assert_int_equal(rc, 2);
	assert_non_null(strstr(out, "--json goes with --dry-run"));
}

static void bad_socket(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char exe[600], out[4096], sock[200];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->d.bindir);
	snprintf(sock, sizeof sock, "%s/nothing.sock", e->d.dir);
	char *argv[] = { exe, "-s", sock, "status", NULL };
	assert_int_equal(daemon_env_run(argv, out, sizeof out), 1);
	assert_non_null(strstr(out, "cannot connect to "));
	assert_non_null(strstr(out, "No such file or directory"));
	assert_non_null(strstr(out, "is clipmapd running? (-s SOCKET)"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(tile_equals_render_and_is_listed),
		cmocka_unit_test(prefetch_completes),
		cmocka_unit_test(prefetch_dry_run),
		cmocka_unit_test(bad_socket),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
