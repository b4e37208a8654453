/* test_view_link — the real viewer over a real shaped link (issue 15): clipmapd in this
 * namespace, build/clipmapview offscreen (320x180, 4 frames a second, so llvmpipe is not the
 * bottleneck) in the client's namespace (ip netns exec), between them tests/support/
 * shaped_link's relay at 4 Mbit/s with 40 ms of delay on what the daemon sends. The viewer
 * flies a flight that holds at one place, jumps 60° of longitude and holds still there,
 * writing one --stats line per frame. From those lines, what the user sees:
 *
 * - issue 15: "at 4 Mbit/s the new place's level 2 is drawn within 2 s": asserted (level 2,
 *   or the coarsest level the viewer wants there when that is finer; + LOAD_SLACK_S). On
 *   this small planet levels 0-2 of the two places share most of their tiles; the printed
 *   per-level times show the finer ones (level 3 at ~3.5 s);
 * - issue 15: "every wanted level within 5 s (with the lossy encodings)": asserted for the
 *   viewer as shipped (it offers the lossy codecs; 0.5 s measured, + LOAD_SLACK_S). With
 *   --lossless (zstd tiles of ~40 KB, ~1.2 MB a level at this place) the link needs 7-9 s, so
 *   there what is asserted is that the viewer fills the new place as fast as the link lets
 *   it: a complete frame within the hold, the tile bytes it received from the jump to that
 *   frame arriving at >= 50 % of the link's rate (nothing stalls: no stale queue, no idle
 *   link), and the lossy run needing at most a third of those bytes (19.8x fewer measured);
 * - issue 15: "a viewer holding still after the jump has ≥ 50 % of its frames complete over
 *   the next 10 s": asserted with the lossy codecs (96 % measured); for both runs, the frames
 *   after the first complete one (a viewer holding still stays complete: ≥ 90 % of those);
 * - issue 15: "its HUD/--stats show link rate, RTT and queue delay": every frame's link_bps,
 *   rtt_ms and queue_ms are present; the highest rate is within a factor of two of the link's,
 *   the least RTT at least the link's; and the mean queue delay the viewer sees is below
 *   QUEUE_MAX_MS: the daemon keeps ~100 ms of the link's rate queued (docs/LINKS.md), and
 *   measured 110-130 ms here, where the daemon's old 8 MiB queue (send_queue_ms = 0,
 *   bbr = false) made it 3.6-3.7 s — with it this test fails only here (its complete frame came
 *   at 13.5 s, inside the hold, the levels 2.5-5 s later than with the window);
 * - issue 15: "screen importance": with zstd tiles the finest level wanted at B is drawn at
 *   least 0.5 s before the first complete frame (a level shows once the middle of its window
 *   is in: view_clipmap_update's cores; 1.75 s measured), where drawing whole windows only
 *   showed it with that frame.
 *
 * Skips, saying why, where namespaces cannot be made or there is no GL context.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "support/daemon_env.h"
#include "support/shaped_link.h"

#define TOKEN "view-link-token"
#define RATE_KBIT 4000
#define DELAY_MS 40
#define FPS 4
#define BEFORE_S 4     /* holding at A before the jump */
#define HOLD_S 14      /* holding at B after it */
#define LOAD_SLACK_S 2 /* scheduling and llvmpipe on a loaded 2-core machine */
#define COARSE_S (2.0 + LOAD_SLACK_S)
#define ISSUE_FULL_S 5.0 /* issue 15's figure for every wanted level (lossy encodings) */
#define QUEUE_MAX_MS 1000 /* the viewer's mean queue_ms, at most */
#define ALT_M 150000 /* metres above the ground (the planet's radius is 1000 km): levels 0-5 */

static struct daemon_env E;
static struct shaped_link L;
static char skip_why[256];

static void stop_daemon(void)
{
	daemon_env_fini(&E);
}

static int setup(void **state)
{
	(void)state;
	char err[256] = "";
	int rc = shaped_link_init(&L, skip_why);
	if (rc == -ENOTSUP) {
		fprintf(stderr, "test_view_link: skipped: %s\n", skip_why);
		return 0;
	}
	if (rc) {
		fprintf(stderr, "test_view_link: %s\n", skip_why);
		return -1;
	}
	skip_why[0] = 0;
	shaped_link_on_fini(stop_daemon);
	if (shaped_link_daemon_start(&L, &E, "clipmapd-vlink", TOKEN, NULL, err)) {
		fprintf(stderr, "test_view_link: %s\n", err);
		shaped_link_fini(&L);
		return -1;
	}
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	daemon_env_fini(&E);
	shaped_link_fini(&L);
	return 0;
}

/* The number after "KEY": in line, or def when absent. */
static double field(const char *line, const char *key, double def)
{
	char k[64];
	snprintf(k, sizeof k, "\"%s\":", key);
	const char *p = strstr(line, k);
	return p ? strtod(p + strlen(k), NULL) : def;
}

/* What one flight showed (run_jump). */
struct jump {
	double coarse_s, full_s, fill_bps, fill_bytes, max_bps, min_rtt, mean_q;
	double finest_s; /* when the finest level wanted at B first showed (-1: never) */
	int held, complete_held, frames, after, complete_10s, frames_10s;
};

static void run_jump(bool lossless, struct jump *o)
{
	if (skip_why[0]) {
		fprintf(stderr, "skipped: %s\n", skip_why);
		skip();
	}
	char err[256];
	if (shaped_link_shape(&L, RATE_KBIT, DELAY_MS, err))
		fail_msg("%s", err);
	char fl[600], stats[600];
	snprintf(fl, sizeof fl, "%s/jump.csv", E.dir);
	snprintf(stats, sizeof stats, "%s/jump.jsonl", E.dir);
	/* one key per frame (--steps 1): FPS × BEFORE_S at A, then FPS × HOLD_S at B */
	FILE *f = fopen(fl, "w");
	assert_non_null(f);
	fprintf(f, "lat,lon,alt,heading,pitch\n");
	for (int i = 0; i < FPS * BEFORE_S; i++)
		fprintf(f, "10,0,%d,0,-40\n", ALT_M);
	for (int i = 0; i < FPS * HOLD_S; i++)
		fprintf(f, "10,60,%d,0,-40\n", ALT_M);
	assert_int_equal(fclose(f), 0);
	char out[16384];
	int rc = shaped_link_view(&L, &E, fl, FPS, lossless, stats, out, sizeof out);
	if (rc == -ENOTSUP) {
		fprintf(stderr, "skipped: %s", out);
		skip();
	}
	if (rc != 0)
		fail_msg("clipmapview exit %d: %s", rc, out);

	f = fopen(stats, "r");
	assert_non_null(f);
	char line[2048];
	int frame = 0, jump = FPS * BEFORE_S, after = 0, complete_after = 0;
	int held = 0, complete_held = 0, level_n = 0; /* frames from the first complete one */
	double t_jump = -1, coarse_s = -1, full_s = -1, max_bps = 0, min_rtt = 1e9;
	double bytes_jump = 0, bytes_full = 0, level_s[16];
	double sum_q = 0;
	int nq = 0, lmin_b = -1, lmax_b = -1, frames_10s = 0, complete_10s = 0;
	while (fgets(line, sizeof line, f)) {
		double t = field(line, "t", -1);
		int lmin = (int)field(line, "lmin", -1), lfirst = (int)field(line, "lfirst", -1);
		int llast = (int)field(line, "llast", -1);
		bool complete = strstr(line, "\"complete\":true") != NULL;
		double bps = field(line, "link_bps", -1), rtt = field(line, "rtt_ms", -1);
		double q = field(line, "queue_ms", -1);
		assert_true(bps >= 0 && rtt >= 0 && q >= 0); /* the viewer reports its link */
		if (bps > max_bps)
			max_bps = bps;
		if (rtt > 0 && rtt < min_rtt)
			min_rtt = rtt;
		if (rtt > 0) {
			sum_q += q;
			nq++;
		}
		/* the frames as figures, for whoever reads a failure */
		printf("frame %2d t %6.2f levels %d-%d drawn %d-%d (%d) detail %d/%d tiles %3d%s "
		       "link %.2f Mbit/s rtt %.0f queue %.0f\n", frame, t, lmin,
		       (int)field(line, "lmax", -1), lfirst, llast, (int)field(line, "levels_drawn", -1),
		       (int)field(line, "ldetail", -1), (int)field(line, "dmax", -1),
		       (int)field(line, "tiles_received", -1), complete ? " complete" : "", bps * 1e-6,
		       rtt, q);
		double bytes = field(line, "link_bytes", -1);
		assert_true(bytes >= 0);
		if (frame == jump) {
			t_jump = t;
			bytes_jump = bytes;
		}
		if (frame >= jump) {
			/* the coarse level to wait for: the coarsest the viewer wants at B, or
			 * level 2 when that is finer (the issue's "level 2") */
			int lc = lmin > 2 ? lmin : 2;
			if (coarse_s < 0 && lfirst >= 0 && lfirst <= lc && llast >= lc)
				coarse_s = t - t_jump;
			if (full_s < 0 && complete) {
				full_s = t - t_jump;
				bytes_full = bytes;
			}
			if (full_s >= 0) {
				held++;
				complete_held += complete;
			}
			/* when each level first shows at B: the finest drawn */
			while (llast >= 0 && level_n <= llast && level_n < 16)
				level_s[level_n++] = t - t_jump;
			after++;
			complete_after += complete;
			if (t - t_jump < 10.0) { /* the issue's "over the next 10 s" */
				frames_10s++;
				complete_10s += complete;
			}
			lmin_b = lmin;
			lmax_b = (int)field(line, "lmax", -1);
		}
		frame++;
	}
	fclose(f);
	double fill_bps = full_s > 0 ? (bytes_full - bytes_jump) * 8 / full_s : 0;
	printf("viewer (%s) over %d kbit/s, %d ms: %d frames (%d after the jump at t %.2f s), levels "
	       "wanted at B %d-%d; after the jump: coarse level drawn at %.2f s (issue: 2 s), "
	       "first complete frame at %.2f s (issue: %.0f s with lossy encodings; %s), %.0f KB "
	       "received until then at %.2f Mbit/s; %d of %d frames complete after the jump "
	       "(%.0f%%; issue: 50%%), %d of %d after the first complete one; viewer's link "
	       "figures: highest rate %.2f Mbit/s, least rtt %.1f ms, mean queue %.0f ms\n",
	       lossless ? "--lossless" : "lossy codecs offered", RATE_KBIT, DELAY_MS, frame, after, t_jump, lmin_b, lmax_b, coarse_s, full_s,
	       ISSUE_FULL_S, full_s >= 0 && full_s <= ISSUE_FULL_S ? "met" : "not met",
	       (bytes_full - bytes_jump) / 1e3, fill_bps * 1e-6, complete_after, after,
	       after ? 100.0 * complete_after / after : 0, complete_held, held, max_bps * 1e-6,
	       min_rtt, nq ? sum_q / nq : -1);
	printf("finest level drawn after the jump, by time:");
	for (int l = 0; l < level_n; l++)
		printf(" L%d %.2f s", l, level_s[l]);
	printf("\n");
	fflush(stdout);
	assert_int_equal(frame, FPS * (BEFORE_S + HOLD_S));
	if (coarse_s < 0)
		fail_msg("the new place's coarse level was never drawn");
	if (full_s < 0)
		fail_msg("no complete frame in the %d s after the jump", HOLD_S);
	*o = (struct jump){ .coarse_s = coarse_s, .full_s = full_s, .fill_bps = fill_bps,
			    .fill_bytes = bytes_full - bytes_jump, .max_bps = max_bps,
			    .min_rtt = min_rtt, .mean_q = nq ? sum_q / nq : 1e9, .held = held,
			    .complete_held = complete_held, .frames = frame, .after = after,
			    .complete_10s = complete_10s, .frames_10s = frames_10s,
			    .finest_s = lmax_b >= 0 && lmax_b < level_n ? level_s[lmax_b] : -1 };
}

static double lossy_bytes = -1; /* what the lossy run received from the jump to complete */

/* The viewer as shipped (it offers the lossy codecs; the daemon uses them below
 * lossy_below_mbit): issue 15's figures, asserted. Runs first, on a cold cache. */
static void jump_over_4mbit_lossy(void **state)
{
	(void)state;
	struct jump j;
	run_jump(false, &j);
	lossy_bytes = j.fill_bytes;
	assert_true(j.coarse_s <= COARSE_S);
	assert_true(j.full_s <= ISSUE_FULL_S + LOAD_SLACK_S); /* every wanted level: 5 s */
	assert_true(j.complete_10s * 2 >= j.frames_10s);	/* ≥ 50 % complete over 10 s */
	assert_true(j.complete_held * 10 >= j.held * 9);
	assert_true(j.min_rtt >= DELAY_MS - 1 && j.min_rtt < 1000);
	assert_true(j.mean_q <= QUEUE_MAX_MS);
	/* the daemon agreed the lossy codecs with this viewer */
	assert_true(daemon_env_log_count(&E, "(lossy on slow links)") >= 1);
}

/* clipmapview --lossless: zstd tiles, so the link is the bottleneck; what is asserted is
 * that the viewer fills the new place as fast as the link lets it, and that the lossy run
 * needed far fewer bytes for the same picture. */
static void jump_over_4mbit_lossless(void **state)
{
	(void)state;
	struct jump j;
	run_jump(true, &j);
	double rate = RATE_KBIT * 1e3;
	assert_true(j.coarse_s <= COARSE_S);
	assert_true(j.fill_bps >= rate / 2);
	assert_true(j.complete_held * 10 >= j.held * 9);
	assert_true(j.max_bps >= rate / 2 && j.max_bps <= rate * 2);
	assert_true(j.min_rtt >= DELAY_MS - 1 && j.min_rtt < 1000);
	assert_true(j.mean_q <= QUEUE_MAX_MS);
	/* screen importance: a level is drawn once the middle of its window is in (its tiles
	 * asked for from the middle out), so the finest wanted level shows while the rest of
	 * its window is still on the link: 1.75 s before the first complete frame here (6.5 s
	 * against 8.25), where drawing only whole windows showed it with that frame */
	printf("finest level at B drawn at %.2f s, the first complete frame at %.2f s\n", j.finest_s,
	       j.full_s);
	assert_true(j.finest_s >= 0 && j.finest_s + 0.5 <= j.full_s);
	if (lossy_bytes > 0) {
		printf("bytes from the jump to the first complete frame: lossy %.0f KB, lossless "
		       "%.0f KB (%.1f×)\n", lossy_bytes / 1e3, j.fill_bytes / 1e3,
		       j.fill_bytes / lossy_bytes);
		assert_true(lossy_bytes * 3 <= j.fill_bytes);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(jump_over_4mbit_lossy),
		cmocka_unit_test(jump_over_4mbit_lossless),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
