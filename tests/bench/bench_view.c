/* bench_view — clipmapview on this machine's GL (Mesa llvmpipe without a GPU): frame time
 * p50/p99 at 1280×720 for an orbit view, 10 km and 2 m above the ground (all levels loaded,
 * camera still), and bytes uploaded per frame in a smooth flight against the minimum (the
 * texels that entered each level's window). The procedural planet, evaluated in-process; the
 * frames are timed once its engine has gone quiet (the view and its prefetch ring loaded).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/resource.h>

#include "client/view/gl_context.h"
#include "client/view/view.h"
#include "client/view/view_source_local.h"
#include "common/xalloc.h"

/* CPU time of the whole process (every llvmpipe thread), ms: steadier than wall time on a
 * shared machine, and what the frame costs in cores. */
static double cpu_ms(void)
{
	struct rusage ru;
	getrusage(RUSAGE_SELF, &ru);
	return (ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) * 1e3 +
	       (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) / 1e3;
}

static int cmp(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

int main(int argc, char **argv)
{
	const char *planet = argc > 1 ? argv[1] : "conf/planets/procedural.ini";
	char err[256];
	struct gl_context *ctx;
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		fprintf(stderr, "bench_view: %s\n", err);
		return 1;
	}
	struct view_source *src;
	if (view_source_local_create(planet, NULL, &src, err) < 0) {
		fprintf(stderr, "bench_view: %s\n", err);
		return 1;
	}
	struct view_desc d = { .width = 1280, .height = 720, .no_prefetch = getenv("BV_NOPF") != NULL };
	struct view *v;
	if (view_create(gl_context_api(ctx), src, &d, &v, err) < 0) {
		fprintf(stderr, "bench_view: %s\n", err);
		return 1;
	}
	printf("view/backend %s, renderer %s, rings 256×16 per level\n", gl_context_backend(ctx),
	       gl_context_renderer(ctx));
	static const struct {
		const char *name;
		struct view_camera c;
	} views[] = {
		{ "orbit 12000 km", { 30, 10, 12e6, 0, -90, 60, 0, 0 } },
		{ "10 km", { -14, -76, 10e3, 45, -15, 60, 0, 0 } },
		{ "2 m", { -14, -76, 2, 45, -5, 60, 0, 0 } },
	};
	enum { NMAX = 240 };
	double ms[NMAX];
	const char *fe = getenv("BENCH_VIEW_FRAMES");
	int N = fe ? atoi(fe) : 24;
	if (N < 2 || N > NMAX)
		N = 24;
	for (size_t i = 0; i < sizeof views / sizeof views[0]; i++) {
		struct view_frame_stats st;
		int frames;
		if (view_frame_complete(v, &views[i].c, 300, &st, &frames) < 0)
			fprintf(stderr, "bench_view: %s: not complete\n", views[i].name);
		/* The in-process engine goes on with the ring around the view (prefetch): let it
		 * finish — a daemon does that work elsewhere — so the frames time the client. */
		for (int k = 0; k < 100 && view_idle(v, 1.0) > 0; k++)
			view_frame(v, &views[i].c, 0, &st);
		double c0 = cpu_ms();
		for (int k = 0; k < N; k++) {
			view_frame(v, &views[i].c, 0, &st);
			ms[k] = st.cpu_ms;
		}
		double cpu = (cpu_ms() - c0) / N;
		qsort(ms, N, sizeof ms[0], cmp);
		printf("view/frame %s 1280x720: p50 %.1f ms, p99 %.1f ms, %llu triangles, levels %d..%d, "
		       "CPU %.1f ms/frame over all threads\n",
		       views[i].name, ms[N / 2], ms[(N * 99) / 100], (unsigned long long)st.triangles,
		       st.lfirst, st.llast, cpu);
	}
	/* A smooth flight at 10 km, 250 m per frame eastwards (900 km/h at 60 fps... a fast jet),
	 * every frame complete: uploaded bytes vs the texels that entered the windows. */
	struct view_camera c = { 20, 30, 10e3, 90, -10, 60, 0, 0 };
	struct view_frame_stats st;
	view_frame_complete(v, &c, 300, &st, NULL);
	struct view_clipmap *cm = view_get_clipmap(v);
	int nl = view_clipmap_levels(cm);
	struct grid_quad *prev = xcalloc((size_t)nl, sizeof *prev);
	bool *had = xcalloc((size_t)nl, sizeof *had);
	for (int l = 0; l < nl; l++) {
		const struct grid_quad *q = view_clipmap_held(cm, l);
		if ((had[l] = q != NULL))
			prev[l] = *q;
	}
	uint64_t up = 0, minb = 0;
	int frames = 60;
	double bpt = 4 + 2 + 4; /* bytes per texel over the three layers */
	for (int f = 0; f < frames; f++) {
		c.lon += 250.0 / (111320.0 * cos(c.lat * M_PI / 180));
		uint64_t before = 0;
		struct view_clipmap_stats cs;
		view_clipmap_get_stats(cm, &cs);
		before = cs.bytes_uploaded;
		view_frame_complete(v, &c, 300, &st, NULL);
		view_clipmap_get_stats(cm, &cs);
		up += cs.bytes_uploaded - before;
		for (int l = 0; l < nl; l++) {
			const struct grid_quad *q = view_clipmap_held(cm, l);
			if (!q)
				continue;
			struct grid_region rg[GRID_MAX_REGIONS];
			int nr = grid_update_regions(had[l] ? &prev[l] : NULL, q, rg);
			for (int r = 0; r < nr; r++)
				minb += (uint64_t)((double)rg[r].w * rg[r].h * bpt);
			prev[l] = *q;
			had[l] = true;
		}
	}
	printf("view/flight 10 km, 250 m/frame: %.1f KiB uploaded per frame, minimum %.1f KiB "
	       "(changed texels only)\n",
	       up / 1024.0 / frames, minb / 1024.0 / frames);
	free(prev);
	free(had);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
	return 0;
}
