/* bench_http — clipmapd's HTTP endpoint under a real load generator (wrk, HTTP/1.1
 * keep-alive): cached tiles per second and latency p50/p99 for PNG colour tiles, float32
 * GeoTIFF heights and Cesium quantized-mesh terrain, and the bytes per tile of each format.
 * The native protocol's cached-tile figures are bench_server's, in the same `make bench` run.
 * Starts build/clipmapd on a temporary config (tests/support/daemon_env) with [http] on an
 * ephemeral loopback port; skips (exit 0, a line saying so) without wrk or curl. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "support/daemon_env.h"

static const char planet[] =
	"[planet]\nname = b\nbody = sphere\nradius = 1000000\ntile_size = 256\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = 3\noctaves = 2\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\nstops = -500 0 0 255, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

/* Level 3: 16 × 8 tiles; the bench cycles through all 128. */
#define Z 3
#define NX 16
#define NY 8

static int run(char *const argv[], char *out, size_t n)
{
	int rc = daemon_env_run(argv, out, n);
	if (rc)
		fprintf(stderr, "bench_http: %s: exit %d: %s\n", argv[0], rc, out);
	return rc;
}

/* wrk's "Latency Distribution" value for pct ("50%"), in ms. */
static double wrk_pct(const char *out, const char *pct)
{
	char key[16];
	snprintf(key, sizeof key, "%s", pct);
	const char *p = strstr(out, "Latency Distribution");
	p = p ? strstr(p, key) : NULL;
	if (!p)
		return -1;
	char unit[8] = "";
	double v = 0;
	if (sscanf(p + strlen(key), " %lf%7s", &v, unit) < 1)
		return -1;
	return !strcmp(unit, "us") ? v / 1000 : !strcmp(unit, "s") ? v * 1000 : v;
}

/* fmt takes two numbers: (row, col) when rowcol, else (x, y). */
static void bench(const char *dir, const char *base, const char *what, const char *fmt,
		  int rowcol)
{
	/* a Lua script that walks every tile of the level in turn */
	char lua[256], out[16384];
	snprintf(lua, sizeof lua, "%s/walk.lua", dir);
	FILE *f = fopen(lua, "w");
	if (!f)
		return;
	fprintf(f, "local i = 0\nrequest = function()\n  local x = i %% %d\n"
		   "  local y = math.floor(i / %d) %% %d\n  i = i + 1\n"
		   "  return wrk.format(nil, string.format(\"%s\", %s))\nend\n",
		NX, NX, NY, fmt, rowcol ? "y, x" : "x, y");
	fclose(f);
	char *const wrk[] = { "wrk", "-t2", "-c8", "-d5s", "--latency", "-s", lua, (char *)base,
			      NULL };
	if (run(wrk, out, sizeof out))
		return;
	if (strstr(out, "walk.lua:")) { /* a script error: wrk would measure "/" instead */
		printf("http/cached %s: wrk's script failed: %s\n", what, out);
		return;
	}
	double rps = 0;
	const char *r = strstr(out, "Requests/sec:");
	if (r)
		rps = atof(r + strlen("Requests/sec:"));
	const char *bad = strstr(out, "Non-2xx or 3xx responses:");
	if (bad) {
		printf("http/cached %s: wrk got errors (%ld): not a figure\n", what,
		       atol(bad + strlen("Non-2xx or 3xx responses:")));
		return;
	}
	printf("http/cached %s: %.0f tiles/s, latency p50 %.2f ms, p99 %.2f ms (wrk, 8 keep-alive "
	       "connections, 2 threads)\n",
	       what, rps, wrk_pct(out, "50%"), wrk_pct(out, "99%"));
}

int main(void)
{
	char probe[256];
	char *const w[] = { "wrk", "--version", NULL }, *const c[] = { "curl", "--version", NULL };
	if (daemon_env_run(w, probe, sizeof probe) > 1 || daemon_env_run(c, probe, sizeof probe)) {
		printf("bench_http: wrk or curl missing (make deps installs them): skipped\n");
		return 0;
	}
	struct daemon_env e;
	char err[256];
	const char *const set[] = { "engine.workers = 2", "log.level = info",
				    "http.listen = 127.0.0.1:0", "http.threads = 2", NULL };
	if (daemon_env_init(&e, "bench_http") || daemon_env_planet_text(&e, "b.ini", planet, NULL) ||
	    daemon_env_start(&e, &(struct daemon_env_conf){ .set = set }, err)) {
		fprintf(stderr, "bench_http: %s\n", err);
		daemon_env_fini(&e);
		return 1;
	}
	daemon_env_log_wait(&e, "http: listening on", 1, 5000);
	char *log = daemon_env_log_read(&e);
	const char *p = strstr(log, "http: listening on http://127.0.0.1:");
	int port = p ? atoi(p + strlen("http: listening on http://127.0.0.1:")) : 0;
	free(log);
	char base[64];
	snprintf(base, sizeof base, "http://127.0.0.1:%d", port);
	/* warm every tile of the level (generation is not what is measured) and weigh one */
	static const struct { const char *what, *fmt, *one; } kinds[] = {
		{ "colour 256² PNG", "/wmts/b/color/" "3" "/%d/%d.png", "/wmts/b/color/3/3/5.png" },
		{ "heights 256² float32 GeoTIFF", "/wmts/b/height/3/%d/%d.tif", "/wmts/b/height/3/3/5.tif" },
		{ "heights 16-bit PNG", "/wmts/b/height/3/%d/%d.png", "/wmts/b/height/3/3/5.png" },
		{ "colour JPEG", "/wmts/b/color/3/%d/%d.jpg", "/wmts/b/color/3/3/5.jpg" },
		{ "colour WebP", "/wmts/b/color/3/%d/%d.webp", "/wmts/b/color/3/3/5.webp" },
		{ "Cesium quantized-mesh 65² vertices", "/cesium/b/3/%d/%d.terrain", "/cesium/b/3/5/4.terrain" },
	};
	char url[256], out[4096];
	for (int y = 0; y < NY; y++)
		for (int x = 0; x < NX; x++) {
			snprintf(url, sizeof url, "%s/wmts/b/color/%d/%d/%d.png", base, Z, y, x);
			char *const cu[] = { "curl", "-s", "-o", "/dev/null", url, NULL };
			daemon_env_run(cu, out, sizeof out);
			snprintf(url, sizeof url, "%s/wmts/b/height/%d/%d/%d.tif", base, Z, y, x);
			char *const ch[] = { "curl", "-s", "-o", "/dev/null", url, NULL };
			daemon_env_run(ch, out, sizeof out);
		}
	for (size_t k = 0; k < sizeof kinds / sizeof kinds[0]; k++) {
		snprintf(url, sizeof url, "%s%s", base, kinds[k].one);
		char *const cu[] = { "curl", "-s", "-o", "/dev/null", "-w", "%{size_download}", url,
				     NULL };
		if (!daemon_env_run(cu, out, sizeof out))
			printf("http/bytes per tile, %s: %ld\n", kinds[k].what, atol(out));
	}
	/* the Cesium path counts y from the south: the format string takes (x, y) as given */
	bench(e.dir, base, kinds[0].what, kinds[0].fmt, 1);
	bench(e.dir, base, kinds[1].what, kinds[1].fmt, 1);
	bench(e.dir, base, kinds[5].what, kinds[5].fmt, 0);
	daemon_env_fini(&e);
	return 0;
}
