/* bench_link — clipmapd over a shaped link (tests/support/shaped_link: namespaces, veth, a
 * relay holding the daemon's sends to a rate with 40 ms of delay): per rate (1, 4, 20,
 * 100 Mbit/s), a session streams a large want-set at one place and jumps to another; the
 * table gives the time to the new place's first tile, to its coarsest level and to all of it
 * (5 levels, 40 tiles of about 50 KB), and the old place's bytes still delivered after the
 * jump — for the daemon as configured (send_queue_ms = 100: the send window sized from the
 * link, BBR asked for) and, in the same run, for its peer with send_queue_ms = 0 and
 * bbr = false (the 8 MiB queue, nothing recalled, the kernel's own buffering and congestion
 * control: the daemon before issue 15), and the configured daemon again with a client that
 * offers the lossy codecs (as clipmapview does: WebP colour, 16-bit heights below
 * lossy_below_mbit, 50 by default), and with a client that takes every tile whole (no
 * TILE_PART: a begun tile cannot be stopped, as before 4 December). Figures, not pass/fail;
 * on a loaded machine read the ratios. Then per rate and configuration the real viewer
 * (clipmapview offscreen, 320x180, 4 frames a second) flies 20 s over the link: lon 0 to 40
 * at lat 10, 150 km up over the test planet (1000 km radius: 35 km/s, levels 0-5), and the
 * share of its frames that were complete is printed (skipped without a GL context).
 * Skips (exit 0, saying why) without root or namespaces.
 * LINK_RATES="4 20" picks rates (Mbit/s); LINK_FLIGHT=0 leaves the flights out; LINK_ONLY=02
 * runs only those configurations (0 window, 1 8 MiB queue, 2 lossy, 3 whole; the ratios of
 * one left out read 0); LINK_DEBUG=1 prints each of the old place's tiles that came after the
 * jump (when, how big, its codec and level) on stderr.
 */
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client/net.h"
#include "common/tilecodec.h"
#include "support/daemon_env.h"
#include "support/shaped_link.h"

#define DELAY_MS 40

static struct daemon_env *running; /* stopped with the link on a signal */

static void stop_daemon(void)
{
	if (running)
		daemon_env_fini(running);
}

static int run_rate(struct shaped_link *sl, struct daemon_env *e, unsigned mbit, uint32_t codecs,
		    bool whole, struct link_jump_result *r)
{
	char err[256];
	if (shaped_link_shape(sl, mbit * 1000, DELAY_MS, err)) {
		fprintf(stderr, "bench_link: %s\n", err);
		return -1;
	}
	uint32_t pid;
	struct net_conn *c = shaped_link_session(sl, e, whole, codecs, &pid, err);
	if (!c) {
		fprintf(stderr, "bench_link: %s\n", err);
		return -1;
	}
	const struct link_jump_plan plan = { .warm_ms = 3000, .a_lmin = 2, .a_lmax = 9,
					     .a_side = 6, .b_lmin = 3, .b_lmax = 7, .b_side = 2,
					     .full = true, .deadline_ms = 60000 };
	int rc = link_jump_run(c, pid, &plan, r, err);
	if (rc)
		fprintf(stderr, "bench_link: %u Mbit/s: %s\n", mbit, err);
	net_close(c);
	return rc;
}

#define FLIGHT_S 20
#define FLIGHT_FPS 4

/* The viewer's 20 s flight over the link: the share of its frames that were complete, or
 * < 0 when it could not run (why printed once). */
static double flight(struct shaped_link *sl, struct daemon_env *e, bool lossless)
{
	static bool told;
	char fl[600], stats[600], out[16384];
	snprintf(fl, sizeof fl, "%s/flight.csv", e->dir);
	snprintf(stats, sizeof stats, "%s/flight.jsonl", e->dir);
	FILE *f = fopen(fl, "w");
	if (!f)
		return -1;
	fprintf(f, "lat,lon,alt,heading,pitch\n");
	for (int i = 0; i < FLIGHT_S * FLIGHT_FPS; i++)
		fprintf(f, "10,%.4f,150000,90,-40\n", 40.0 * i / (FLIGHT_S * FLIGHT_FPS - 1));
	if (fclose(f))
		return -1;
	int rc = shaped_link_view(sl, e, fl, FLIGHT_FPS, lossless, stats, out, sizeof out);
	if (rc) {
		if (!told)
			fprintf(stderr, "bench_link: flights skipped: clipmapview %d: %s\n", rc, out);
		told = true;
		return -1;
	}
	f = fopen(stats, "r");
	if (!f)
		return -1;
	char line[2048];
	int frames = 0, complete = 0;
	while (fgets(line, sizeof line, f)) {
		frames++;
		complete += strstr(line, "\"complete\":true") != NULL;
	}
	fclose(f);
	return frames ? (double)complete / frames : -1;
}

static void fmt_ms(char *out, size_t n, double ms)
{
	if (ms < 0)
		snprintf(out, n, "> 60 s");
	else
		snprintf(out, n, "%.0f ms", ms);
}

int main(void)
{
	struct shaped_link sl;
	char why[256];
	int rc = shaped_link_init(&sl, why);
	if (rc == -ENOTSUP) {
		printf("bench_link: skipped: %s\n", why);
		return 0;
	}
	if (rc) {
		fprintf(stderr, "bench_link: %s\n", why);
		return 1;
	}
	unsigned rates[8] = { 1, 4, 20, 100 };
	int nr = 4;
	const char *env = getenv("LINK_RATES");
	if (env && *env) {
		nr = 0;
		for (char *p = (char *)env, *end; *p && nr < 8; p = end) {
			unsigned long v = strtoul(p, &end, 10);
			if (end == p || !v) {
				fprintf(stderr, "bench_link: LINK_RATES: \"%s\" is not a list of Mbit/s\n",
					env);
				return 2;
			}
			rates[nr++] = (unsigned)v;
		}
	}
	printf("link jump: %d ms delay; A: levels 2-9, 6x6 tiles each, 2 layers; B: levels 3-7, "
	       "2x2 tiles, 2 layers (40 tiles); 128^2 tiles (~50 KB with zstd)\n", DELAY_MS);
	printf("%-10s %-16s %10s %10s %10s %12s %12s %12s\n", "rate", "daemon", "first", "coarse",
	       "all", "stale", "goodput", "20 s flight");
	enum { NK = 4 };
	struct link_jump_result res[NK][8];
	const char *names[NK] = { "window 100 ms", "8 MiB queue", "window + lossy",
				  "window, whole" };
	const char *queues[NK] = { "session.send_queue_ms = 100", "session.send_queue_ms = 0",
				   "session.send_queue_ms = 100", "session.send_queue_ms = 100" };
	const char *ccs[NK] = { "session.bbr = true", "session.bbr = false", "session.bbr = true",
				"session.bbr = true" };
	const uint32_t codecs[NK] = { 0, 0, TCODEC_ALL_MASK, 0 };
	const bool whole[NK] = { false, false, false, true }; /* the client takes no TILE_PART */
	int failed = 0;
	for (int k = 0; k < NK; k++) {
		if (getenv("LINK_ONLY") && !strchr(getenv("LINK_ONLY"), '0' + k))
			continue;
		struct daemon_env e;
		char tcp[64], err[256];
		snprintf(tcp, sizeof tcp, "listen.tcp = %s:0", sl.addr);
		const char *set[] = { tcp, queues[k], ccs[k], "engine.workers = 2", "engine.cache_mb = 512",
				      "session.max_rate = 1000", "log.level = info", NULL };
		const struct daemon_env_conf conf = { .set = set, .token = "bench-link-token" };
		running = &e;
		shaped_link_on_fini(stop_daemon);
		if (daemon_env_init(&e, "clipmapd-bench-link") ||
		    daemon_env_planet_text(&e, "test.ini", shaped_link_planet, NULL) ||
		    daemon_env_start(&e, &conf, err)) {
			fprintf(stderr, "bench_link: %s\n", err);
			daemon_env_fini(&e);
			shaped_link_fini(&sl);
			return 1;
		}
		for (int i = 0; i < nr; i++) {
			struct link_jump_result *r = &res[k][i];
			if (run_rate(&sl, &e, rates[i], codecs[k], whole[k], r)) {
				failed = 1;
				continue;
			}
			char rate[16], f[16], co[16], all[16], st[24], gp[24];
			snprintf(rate, sizeof rate, "%u Mbit/s", rates[i]);
			fmt_ms(f, sizeof f, r->first_ms);
			fmt_ms(co, sizeof co, r->coarse_ms);
			fmt_ms(all, sizeof all, r->full_ms);
			snprintf(st, sizeof st, "%.0f KB", (double)r->stale_bytes / 1000);
			snprintf(gp, sizeof gp, "%.2f Mbit/s", r->warm_bps * 1e-6);
			const char *fe = getenv("LINK_FLIGHT");
			double fc = (fe && atoi(fe) == 0) || whole[k] ? -1
									: flight(&sl, &e, codecs[k] == 0);
			char fs[24] = "-";
			if (fc >= 0)
				snprintf(fs, sizeof fs, "%.0f%% complete", 100 * fc);
			printf("%-10s %-16s %10s %10s %10s %12s %12s %12s\n", rate, names[k], f, co, all,
			       st, gp, fs);
			fflush(stdout);
		}
		daemon_env_fini(&e);
		running = NULL;
	}
	printf("ratios (8 MiB queue over window; > 1: the window is faster; stale: window vs queue)\n");
	for (int i = 0; i < nr; i++) {
		const struct link_jump_result *a = &res[0][i], *b = &res[1][i];
		if (a->full_ms < 0 || b->full_ms < 0) {
			char fa[16], fb[16], la[16], lb[16];
			fmt_ms(fa, sizeof fa, a->first_ms);
			fmt_ms(fb, sizeof fb, b->first_ms);
			fmt_ms(la, sizeof la, a->full_ms);
			fmt_ms(lb, sizeof lb, b->full_ms);
			printf("  %u Mbit/s: first tile %s vs %s, all of B %s vs %s, stale bytes %.0f KB "
			       "vs %.0f KB\n", rates[i], fa, fb, la, lb, (double)a->stale_bytes / 1000,
			       (double)b->stale_bytes / 1000);
			continue;
		}
		printf("  %u Mbit/s: first tile %.1fx, all of B %.1fx, stale bytes %.0f KB vs "
		       "%.0f KB\n", rates[i], b->first_ms / (a->first_ms > 0 ? a->first_ms : 1),
		       b->full_ms / (a->full_ms > 0 ? a->full_ms : 1),
		       (double)a->stale_bytes / 1000, (double)b->stale_bytes / 1000);
	}
	printf("lossy over lossless (window; > 1: lossy is faster)\n");
	for (int i = 0; i < nr; i++) {
		const struct link_jump_result *a = &res[0][i], *l = &res[2][i];
		if (a->full_ms > 0 && l->full_ms > 0)
			printf("  %u Mbit/s: coarsest level %.1fx, all of B %.1fx\n", rates[i],
			       a->coarse_ms / (l->coarse_ms > 0 ? l->coarse_ms : 1),
			       a->full_ms / l->full_ms);
	}
	printf("tiles in parts over whole tiles (window, lossless): the new place's first tile "
	       "and the old place's bytes after the jump\n");
	for (int i = 0; i < nr; i++) {
		const struct link_jump_result *a = &res[0][i], *w = &res[3][i];
		char fa[16], fw[16];
		fmt_ms(fa, sizeof fa, a->first_ms);
		fmt_ms(fw, sizeof fw, w->first_ms);
		printf("  %u Mbit/s: first tile %s vs %s, stale %.1f KB vs %.1f KB (150 ms of the "
		       "link: %.1f KB)\n", rates[i], fa, fw, (double)a->stale_bytes / 1000,
		       (double)w->stale_bytes / 1000, rates[i] * 1e6 * 0.150 / 8 / 1000);
	}
	shaped_link_fini(&sl);
	return failed;
}
