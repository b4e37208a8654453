/* bench_view — clipmapview on this machine's GL (Mesa llvmpipe without a GPU): frame time
 * p50/p99 at 1280×720 for an orbit view, 10 km and 2 m above the ground (all levels loaded,
 * camera still), and bytes uploaded per frame in a smooth flight against the minimum (the
 * texels that entered each level's window). The procedural planet, evaluated in-process; the
 * frames are timed once its engine has gone quiet (the view and its prefetch ring loaded).
 * BV_NORMALS=fetch|derive picks where the normals come from (default auto: made from the
 * heights as they are uploaded, on this planet; the flight line then says what that cost).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#include <EGL/egl.h>

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

/* Pipeline statistics (ARB_pipeline_statistics_query, in llvmpipe): the work of one frame in
 * counts that do not depend on the machine's load. */
#define GL_VERTEX_SHADER_INVOCATIONS_ARB 0x82F0
#define GL_CLIPPING_OUTPUT_PRIMITIVES_ARB 0x82F7
#define GL_FRAGMENT_SHADER_INVOCATIONS_ARB 0x82F4
static const GLenum stat_kind[4] = { GL_VERTEX_SHADER_INVOCATIONS_ARB,
				     GL_CLIPPING_OUTPUT_PRIMITIVES_ARB,
				     GL_FRAGMENT_SHADER_INVOCATIONS_ARB, GL_SAMPLES_PASSED };
static struct {
	PFNGLGENQUERIESPROC gen;
	PFNGLBEGINQUERYPROC begin;
	PFNGLENDQUERYPROC end;
	PFNGLGETQUERYOBJECTUI64VPROC get;
	unsigned q[4];
} stats;

static void stats_init(const struct gl_context *ctx)
{
	const char *ext = (const char *)gl_context_api(ctx)->GetString(GL_RENDERER);
	if (strcmp(gl_context_backend(ctx), "egl") != 0 || !ext)
		return;
	stats.gen = (PFNGLGENQUERIESPROC)eglGetProcAddress("glGenQueries");
	stats.begin = (PFNGLBEGINQUERYPROC)eglGetProcAddress("glBeginQuery");
	stats.end = (PFNGLENDQUERYPROC)eglGetProcAddress("glEndQuery");
	stats.get = (PFNGLGETQUERYOBJECTUI64VPROC)eglGetProcAddress("glGetQueryObjectui64v");
	if (!stats.gen || !stats.begin || !stats.end || !stats.get) {
		stats.gen = NULL;
		return;
	}
	stats.gen(4, stats.q);
}

/* One frame of camera c with the statistics queries around it: out[] = vertex shader
 * invocations, primitives out of clipping, fragments rasterized (llvmpipe counts them before
 * the depth test), fragments that passed the depth test (shaded: llvmpipe tests depth
 * first); all 0 without the queries. */
static void frame_counted(const struct gl_context *ctx, struct view *v,
			  const struct view_camera *c, uint64_t out[4])
{
	struct view_frame_stats st;
	out[0] = out[1] = out[2] = out[3] = 0;
	if (!stats.gen) {
		view_frame(v, c, 0, &st);
		return;
	}
	/* one query active at a time (a frame each) */
	for (int k = 0; k < 4; k++) {
		stats.begin(stat_kind[k], stats.q[k]);
		view_frame(v, c, 0, &st);
		stats.end(stat_kind[k]);
		stats.get(stats.q[k], GL_QUERY_RESULT, &out[k]);
	}
	if (gl_context_api(ctx)->GetError() != GL_NO_ERROR)
		out[0] = out[1] = out[2] = out[3] = 0;
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
	/* BV_NORMALS=fetch|derive (default: auto, which derives on the procedural planet) */
	const char *bn = getenv("BV_NORMALS");
	if (bn && !strcmp(bn, "derive"))
		d.normals = VIEW_NORMALS_DERIVE;
	else if (bn && !strcmp(bn, "fetch"))
		d.normals = VIEW_NORMALS_FETCH;
	struct view *v;
	if (view_create(gl_context_api(ctx), src, &d, &v, err) < 0) {
		fprintf(stderr, "bench_view: %s\n", err);
		return 1;
	}
	stats_init(ctx);
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
	const char *only = getenv("BV_ONLY"); /* time only the view of this name ("2 m") */
	for (size_t i = 0; i < sizeof views / sizeof views[0]; i++) {
		if (only && strcmp(only, views[i].name) != 0)
			continue;
		struct view_frame_stats st;
		int frames;
		if (view_frame_complete(v, &views[i].c, 300, &st, &frames) < 0)
			fprintf(stderr, "bench_view: %s: not complete\n", views[i].name);
		/* The in-process engine goes on with the ring around the view (prefetch): let it
		 * finish — a daemon does that work elsewhere — so the frames time the client. */
		for (int k = 0; k < 100 && view_idle(v, 1.0) > 0; k++)
			view_frame(v, &views[i].c, 0, &st);
		/* BV_MOVE=M: the camera steps M metres east each frame (no tile waits: what the
		 * per-frame work costs in flight, the textures as they are) */
		double move = getenv("BV_MOVE") ? atof(getenv("BV_MOVE")) : 0;
		struct view_camera cm = views[i].c;
		double c0 = cpu_ms(), cmin = INFINITY;
		for (int k = 0; k < N; k++) {
			double c1 = cpu_ms();
			cm.lon += move / (111320.0 * cos(cm.lat * M_PI / 180));
			view_frame(v, &cm, 0, &st);
			ms[k] = st.cpu_ms;
			cmin = fmin(cmin, cpu_ms() - c1);
		}
		double cpu = (cpu_ms() - c0) / N;
		uint64_t cnt[4];
		frame_counted(ctx, v, &views[i].c, cnt);
		qsort(ms, N, sizeof ms[0], cmp);
		printf("view/frame %s 1280x720: p50 %.1f ms, p99 %.1f ms, %llu triangles, levels %d..%d, "
		       "CPU %.1f ms/frame over all threads (least %.1f)\n",
		       views[i].name, ms[N / 2], ms[(N * 99) / 100], (unsigned long long)st.triangles,
		       st.lfirst, st.llast, cpu, cmin);
		if (cnt[2])
			printf("view/work %s: %llu vertex shader invocations, %llu primitives "
			       "rasterized, %llu fragments rasterized, %llu shaded (%.2f per pixel)\n",
			       views[i].name, (unsigned long long)cnt[0],
			       (unsigned long long)cnt[1], (unsigned long long)cnt[2],
			       (unsigned long long)cnt[3], (double)cnt[3] / (d.width * d.height));
	}
	if (getenv("BV_NOFLIGHT")) /* the frame times only */
		goto out;
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
	uint64_t up = 0, minb = 0, dn0, dt0;
	int frames = 60;
	{
		struct view_clipmap_stats cs;
		view_clipmap_get_stats(cm, &cs);
		dn0 = cs.normals_derived;
		dt0 = cs.derive_ns;
	}
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
	struct view_clipmap_stats ce;
	view_clipmap_get_stats(cm, &ce);
	if (ce.normals_derived > dn0)
		printf("view/flight normals derived: %.0f texels, %.2f ms per frame (%.1f ns a "
		       "texel)\n",
		       (double)(ce.normals_derived - dn0) / frames,
		       (double)(ce.derive_ns - dt0) * 1e-6 / frames,
		       (double)(ce.derive_ns - dt0) / (double)(ce.normals_derived - dn0));
	free(prev);
	free(had);
out:
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
	return 0;
}
