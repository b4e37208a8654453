/* view — see view.h. Design notes:
 * - Geometry: NR = nlevels rings of m circles of n vertices (θ̃ geometric within a ring,
 *   halving per level, seed 000 §3.4) plus the nadir vertex; uploaded once. A level drawn as
 *   a full disk uses its ring, the two finer rings (still finer than its texels need) and a
 *   fan to the nadir.
 * - Culling: each ring (and fan) is split into NSEC sectors of φ̃, each one index range
 *   (ring-major, then sector, then circle). Per frame the CPU tests each sector's bounds
 *   (view_sector_visible: its θ̃ × φ̃ patch at the terrain's height bounds, placed in doubles
 *   as the shader does, inflated by the patch's bulge) against the frustum's side planes, the
 *   plane behind the camera and the horizon cap, and draws the visible ranges, contiguous
 *   ones merged. The triangle order is the same with culling off, so the pixels are too.
 * - Blending: over the outer 40 % of a ring the height, colour and normal fade to the next
 *   coarser level, reaching it exactly on the boundary, so neighbouring rings share
 *   bit-identical boundary vertices (no cracks) and no level boundary pops.
 * - Precision: the shader works with n − up (the direction from the nadir) and differences of
 *   radii; the camera sits at the origin of its east-north-up frame.
 */
#include "view.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "xalloc.h"

#include "terrain_frag.h"
#include "terrain_vert.h"

#define DEG (M_PI / 180.0)
#define MAX_WANTS 4096

enum {
	U_VP, U_LAT, U_BODY, U_A, U_CAP, U_R, U_T, U_PF, U_VF, U_SF, U_PC, U_VC, U_SC, U_FADE,
	U_HEIGHT, U_NORMAL, U_COLOR, U_SUN, U_HAZE, U_LAYERS, U_EXAG, U_COUNT
};
static const char *const uniform_names[U_COUNT] = {
	"u_vp", "u_lat", "u_body", "u_a", "u_cap", "u_R", "u_T", "u_pf", "u_vf", "u_sf", "u_pc",
	"u_vc", "u_sc", "u_fade", "u_height", "u_normal", "u_color", "u_sun", "u_haze", "u_layers",
	"u_exag",
};

struct view {
	const struct gl *gl;
	struct view_source *src;
	struct view_desc d;
	struct view_body body;
	struct view_clipmap *cm;
	int nlevels, max_level;
	uint32_t T;
	/* geometry */
	unsigned vao, vbo, ibo;
	int nsec;		 /* sectors per ring */
	size_t *sec_first;	 /* ring i sector s: [sec_first[i·nsec+s], sec_first[i·nsec+s+1]) */
	size_t *fan_first;	 /* per circle-boundary k·m (k = 1..NR), n·3 indices each */
	bool cull;
	/* program */
	unsigned prog;
	int u[U_COUNT];
	/* framebuffer */
	unsigned fbo, color_tex, depth_tex;
	bool reversed;
	/* state */
	struct view_want *wants;
	bool sent_once;
	bool *was_usable;
	double *ready_since;
	struct view_camera last;
	unsigned char bg[4];
};

static double now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

static unsigned compile(const struct gl *gl, GLenum type, const char *src, const char *name,
			char err[256])
{
	unsigned s = gl->CreateShader(type);
	gl->ShaderSource(s, 1, &src, NULL);
	gl->CompileShader(s);
	int ok = 0;
	gl->GetShaderiv(s, GL_COMPILE_STATUS, &ok);
	if (!ok) {
		char log[200] = "";
		gl->GetShaderInfoLog(s, sizeof log, NULL, log);
		snprintf(err, 256, "%s: %s", name, log);
		gl->DeleteShader(s);
		return 0;
	}
	return s;
}

static int build_program(struct view *v, char err[256])
{
	const struct gl *gl = v->gl;
	unsigned vs = compile(gl, GL_VERTEX_SHADER, terrain_vert_src, "terrain.vert", err);
	if (!vs)
		return -EINVAL;
	unsigned fs = compile(gl, GL_FRAGMENT_SHADER, terrain_frag_src, "terrain.frag", err);
	if (!fs) {
		gl->DeleteShader(vs);
		return -EINVAL;
	}
	v->prog = gl->CreateProgram();
	gl->AttachShader(v->prog, vs);
	gl->AttachShader(v->prog, fs);
	gl->LinkProgram(v->prog);
	gl->DeleteShader(vs);
	gl->DeleteShader(fs);
	int ok = 0;
	gl->GetProgramiv(v->prog, GL_LINK_STATUS, &ok);
	if (!ok) {
		char log[200] = "";
		gl->GetProgramInfoLog(v->prog, sizeof log, NULL, log);
		snprintf(err, 256, "terrain program: %s", log);
		return -EINVAL;
	}
	for (int i = 0; i < U_COUNT; i++)
		v->u[i] = gl->GetUniformLocation(v->prog, uniform_names[i]);
	return 0;
}

/* θ̃ of circle c (c = ring·m + j). */
static double circle_theta(int c, int m)
{
	int i = c / m, j = c % m;
	double r0 = view_ring_radius(i), r1 = view_ring_radius(i + 1);
	return r0 * pow(r1 / r0, (double)j / m);
}

/* The first φ̃ step of sector s. */
static int sector_k(const struct view *v, int s) { return s * v->d.n_phi / v->nsec; }

static void build_geometry(struct view *v)
{
	const struct gl *gl = v->gl;
	int n = v->d.n_phi, m = v->d.m_rings, NR = v->nlevels;
	int ncirc = NR * m + 1;
	size_t nvert = (size_t)ncirc * n + 1;
	float *vert = xmalloc(nvert * 3 * sizeof *vert);
	for (int c = 0; c < ncirc; c++) {
		double th = circle_theta(c, m);
		for (int k = 0; k < n; k++) {
			double ph = 2 * M_PI * k / n;
			float *p = vert + ((size_t)c * n + k) * 3;
			p[0] = (float)sin(ph);
			p[1] = (float)cos(ph);
			p[2] = (float)th;
		}
	}
	float *centre = vert + (nvert - 1) * 3;
	centre[0] = 0;
	centre[1] = 1;
	centre[2] = 0;
	size_t nidx = (size_t)NR * m * n * 6 + (size_t)NR * n * 3;
	uint32_t *idx = xmalloc(nidx * sizeof *idx);
	v->nsec = n < 32 ? n : 32;
	v->sec_first = xcalloc((size_t)NR * v->nsec + 1, sizeof *v->sec_first);
	v->fan_first = xcalloc((size_t)NR + 1, sizeof *v->fan_first);
	size_t q = 0;
	for (int i = 0; i < NR; i++)
		for (int sec = 0; sec < v->nsec; sec++) {
			v->sec_first[i * v->nsec + sec] = q;
			for (int c = i * m; c < (i + 1) * m; c++)
				for (int k = sector_k(v, sec); k < sector_k(v, sec + 1); k++) {
					uint32_t a = (uint32_t)(c * n + k);
					uint32_t b = (uint32_t)(c * n + (k + 1) % n);
					uint32_t a2 = a + (uint32_t)n, b2 = b + (uint32_t)n;
					idx[q++] = a;
					idx[q++] = b;
					idx[q++] = b2;
					idx[q++] = a;
					idx[q++] = b2;
					idx[q++] = a2;
				}
		}
	v->sec_first[NR * v->nsec] = q;
	for (int k1 = 1; k1 <= NR; k1++) {
		v->fan_first[k1] = q;
		int c = k1 * m;
		for (int k = 0; k < n; k++) {
			idx[q++] = (uint32_t)(c * n + k);
			idx[q++] = (uint32_t)(c * n + (k + 1) % n);
			idx[q++] = (uint32_t)(nvert - 1);
		}
	}
	gl->GenVertexArrays(1, &v->vao);
	gl->BindVertexArray(v->vao);
	gl->GenBuffers(1, &v->vbo);
	gl->BindBuffer(GL_ARRAY_BUFFER, v->vbo);
	gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(nvert * 3 * sizeof *vert), vert, GL_STATIC_DRAW);
	gl->GenBuffers(1, &v->ibo);
	gl->BindBuffer(GL_ELEMENT_ARRAY_BUFFER, v->ibo);
	gl->BufferData(GL_ELEMENT_ARRAY_BUFFER, (GLsizeiptr)(q * sizeof *idx), idx, GL_STATIC_DRAW);
	gl->VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), NULL);
	gl->EnableVertexAttribArray(0);
	gl->BindVertexArray(0);
	free(vert);
	free(idx);
}

static int build_fbo(struct view *v, char err[256])
{
	const struct gl *gl = v->gl;
	gl->GenTextures(1, &v->color_tex);
	gl->BindTexture(GL_TEXTURE_2D, v->color_tex);
	gl->TexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, v->d.width, v->d.height, 0, GL_RGBA,
		       GL_UNSIGNED_BYTE, NULL);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
	gl->GenTextures(1, &v->depth_tex);
	gl->BindTexture(GL_TEXTURE_2D, v->depth_tex);
	gl->TexImage2D(GL_TEXTURE_2D, 0, v->reversed ? GL_DEPTH_COMPONENT32F : GL_DEPTH_COMPONENT24,
		       v->d.width, v->d.height, 0, GL_DEPTH_COMPONENT, GL_FLOAT, NULL);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
	gl->GenFramebuffers(1, &v->fbo);
	gl->BindFramebuffer(GL_FRAMEBUFFER, v->fbo);
	gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, v->color_tex, 0);
	gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, v->depth_tex, 0);
	GLenum st = gl->CheckFramebufferStatus(GL_FRAMEBUFFER);
	if (st != GL_FRAMEBUFFER_COMPLETE) {
		snprintf(err, 256, "framebuffer %dx%d incomplete (0x%x)", v->d.width, v->d.height, st);
		return -EINVAL;
	}
	return 0;
}

int view_create(const struct gl *gl, struct view_source *src, const struct view_desc *d,
		struct view **out, char err[256])
{
	*out = NULL;
	struct view *v = xcalloc(1, sizeof *v);
	v->gl = gl;
	v->src = src;
	if (d)
		v->d = *d;
	if (v->d.width <= 0 || v->d.height <= 0) {
		v->d.width = 1280;
		v->d.height = 720;
	}
	if (v->d.n_phi <= 0)
		v->d.n_phi = 256;
	if (v->d.m_rings <= 0)
		v->d.m_rings = 16;
	if (v->d.sun_az == 0 && v->d.sun_el == 0) {
		v->d.sun_az = 135;
		v->d.sun_el = 35;
	}
	if (!(v->d.exaggeration > 0))
		v->d.exaggeration = 1;
	if (v->d.haze == 0)
		v->d.haze = 1;
	const struct view_planet *p = &src->planet;
	view_body_init(&v->body, p->a, p->f);
	v->body.hmin *= v->d.exaggeration;
	v->body.hmax *= v->d.exaggeration;
	v->max_level = p->max_level < GRID_MAX_LEVEL ? p->max_level : GRID_MAX_LEVEL;
	v->nlevels = v->max_level + 1;
	v->T = p->tile_size;
	v->reversed = gl->ClipControl != NULL;
	const char *nc = getenv("CLIPMAP_NO_CULL");
	v->cull = !v->d.no_cull && !(nc && strcmp(nc, "1") == 0);
	v->wants = xmalloc(MAX_WANTS * sizeof *v->wants);
	v->was_usable = xcalloc((size_t)v->nlevels, sizeof *v->was_usable);
	v->ready_since = xcalloc((size_t)v->nlevels, sizeof *v->ready_since);
	int rc = view_clipmap_create(gl, src, v->nlevels, &v->cm, err);
	if (rc == 0)
		rc = build_program(v, err);
	if (rc == 0) {
		build_geometry(v);
		rc = build_fbo(v, err);
	}
	if (rc == 0) {
		GLenum e = gl->GetError();
		if (e != GL_NO_ERROR) {
			snprintf(err, 256, "view setup: GL error 0x%x", e);
			rc = -EIO;
		}
	}
	if (rc < 0) {
		view_destroy(v);
		return rc;
	}
	*out = v;
	return 0;
}

static void free_fbo(struct view *v);

void view_destroy(struct view *v)
{
	if (!v)
		return;
	const struct gl *gl = v->gl;
	view_clipmap_destroy(v->cm);
	if (v->prog)
		gl->DeleteProgram(v->prog);
	if (v->vao)
		gl->DeleteVertexArrays(1, &v->vao);
	if (v->vbo)
		gl->DeleteBuffers(1, &v->vbo);
	if (v->ibo)
		gl->DeleteBuffers(1, &v->ibo);
	free_fbo(v);
	free(v->sec_first);
	free(v->fan_first);
	free(v->wants);
	free(v->was_usable);
	free(v->ready_since);
	free(v);
}

/* Whether level l can be drawn out to angle r: its texture holds a window that covers it. */
static bool usable(struct view *v, int l, double r)
{
	view_clipmap_update(v->cm, l);
	const struct grid_quad *h = view_clipmap_held(v->cm, l);
	return h && view_window_covers(h, v->last.lon, v->last.lat, r, 1.5);
}

static void level_uniforms(struct view *v, int l, int up, int uv, int us)
{
	const struct gl *gl = v->gl;
	double p[6];
	view_level_params(view_clipmap_held(v->cm, l), v->last.lon, v->last.lat, p);
	gl->Uniform4f(up, (float)p[0], (float)p[1], (float)p[2], (float)p[3]);
	gl->Uniform2f(uv, (float)p[4], (float)p[5]);
	gl->Uniform1f(us, (float)l);
}

void view_set_culling(struct view *v, bool on) { v->cull = on; }

/* Index ranges drawn as few calls: a range adjoining the pending one extends it. */
struct ranges {
	const struct gl *gl;
	size_t first, count;
};

static void ranges_flush(struct ranges *r)
{
	if (r->count)
		r->gl->DrawElements(GL_TRIANGLES, (GLsizei)r->count, GL_UNSIGNED_INT,
				    (const void *)(r->first * sizeof(uint32_t)));
	r->count = 0;
}

static void ranges_add(struct ranges *r, size_t first, size_t count)
{
	if (r->count && r->first + r->count == first) {
		r->count += count;
		return;
	}
	ranges_flush(r);
	r->first = first;
	r->count = count;
}

/* Draws sector s of the geometry over θ̃ ∈ [th0, th1] (indices [first, first + count)) if
 * visible; counts its indices in *drawn or *culled. */
static void draw_sector(struct view *v, struct ranges *r, double th0, double th1, int s,
			size_t first, size_t count, double cap, uint64_t *drawn, uint64_t *culled)
{
	double ph0 = 2 * M_PI * sector_k(v, s) / v->d.n_phi;
	double ph1 = 2 * M_PI * sector_k(v, s + 1) / v->d.n_phi;
	if (v->cull && !view_sector_visible(&v->body, &v->last, th0, th1, ph0, ph1, cap)) {
		*culled += count;
		return;
	}
	ranges_add(r, first, count);
	*drawn += count;
}

static uint64_t draw_level(struct view *v, int i, bool ring, bool first, double fade,
			   double cap, uint64_t *culled)
{
	const struct gl *gl = v->gl;
	level_uniforms(v, i, v->u[U_PF], v->u[U_VF], v->u[U_SF]);
	int c = (first || i == 0) ? i : i - 1;
	level_uniforms(v, c, v->u[U_PC], v->u[U_VC], v->u[U_SC]);
	gl->Uniform1f(v->u[U_R], (float)view_ring_radius(i));
	gl->Uniform1f(v->u[U_FADE], ring ? 1.0f : (float)fade);
	uint64_t idx = 0, cidx = 0;
	int last = ring ? i : (i + 2 < v->nlevels - 1 ? i + 2 : v->nlevels - 1);
	struct ranges r = { gl, 0, 0 };
	for (int j = i; j <= last; j++)
		for (int s = 0; s < v->nsec; s++) {
			size_t f = v->sec_first[j * v->nsec + s];
			draw_sector(v, &r, view_ring_radius(j + 1), view_ring_radius(j), s, f,
				    v->sec_first[j * v->nsec + s + 1] - f, cap, &idx, &cidx);
		}
	if (!ring)
		for (int s = 0; s < v->nsec; s++) {
			size_t f = v->fan_first[last + 1] + (size_t)sector_k(v, s) * 3;
			size_t n = (size_t)(sector_k(v, s + 1) - sector_k(v, s)) * 3;
			draw_sector(v, &r, 0, view_ring_radius(last + 1), s, f, n, cap, &idx, &cidx);
		}
	ranges_flush(&r);
	*culled += cidx / 3;
	return idx / 3;
}

static void set_targets(struct view *v, int lmin, int lmax, bool *changed)
{
	for (int l = 0; l < v->nlevels; l++) {
		if (l != 0 && (l < lmin || l > lmax)) {
			*changed |= view_clipmap_target(v->cm, l, NULL);
			continue;
		}
		const struct grid_quad *cur = view_clipmap_target_of(v->cm, l);
		int lx = view_level_lx(l, v->last.lat, cur ? cur->lx : -1);
		struct grid_quad q;
		grid_quad(lx, l, v->T, v->last.lon, v->last.lat, &q);
		*changed |= view_clipmap_target(v->cm, l, &q);
	}
}

static void common_uniforms(struct view *v, double agl, double cap)
{
	const struct gl *gl = v->gl;
	const struct view_camera *c = &v->last;
	double sl = sin(c->lat * DEG), cl = cos(c->lat * DEG);
	double N = view_body_n(&v->body, sl);
	double near = fmin(fmax(agl * 0.25, 0.01), 1e5);
	double far = sqrt(fmax(0, (v->body.a + c->alt) * (v->body.a + c->alt) -
				       (v->body.a + v->body.hmin) * (v->body.a + v->body.hmin))) +
		     sqrt((v->body.a + v->body.hmax) * (v->body.a + v->body.hmax) -
			  (v->body.a + v->body.hmin) * (v->body.a + v->body.hmin)) +
		     2 * fabs(c->alt);
	float vp[16];
	view_camera_matrix(c, v->reversed, near, far, vp);
	gl->UniformMatrix4fv(v->u[U_VP], 1, GL_FALSE, vp);
	gl->Uniform3f(v->u[U_LAT], (float)sl, (float)cl, (float)(c->lat * DEG));
	gl->Uniform4f(v->u[U_BODY], (float)(N + c->alt), (float)c->alt, (float)N, (float)v->body.e2);
	gl->Uniform1f(v->u[U_A], (float)v->body.a);
	gl->Uniform1f(v->u[U_CAP], (float)cap);
	gl->Uniform1f(v->u[U_T], (float)v->T);
	gl->Uniform1i(v->u[U_HEIGHT], 0);
	gl->Uniform1i(v->u[U_NORMAL], 1);
	gl->Uniform1i(v->u[U_COLOR], 2);
	/* The sun: azimuth/elevation at the camera → the frame with the camera on meridian 0
	 * (x: lat 0 lon 0 direction, y: east, z: north). */
	double az = v->d.sun_az * DEG, el = v->d.sun_el * DEG;
	double e = sin(az) * cos(el), n = cos(az) * cos(el), u = sin(el);
	gl->Uniform3f(v->u[U_SUN], (float)(-sl * n + cl * u), (float)e, (float)(cl * n + sl * u));
	gl->Uniform4f(v->u[U_HAZE], 8000.0f * v->d.exaggeration, v->d.haze > 0 ? v->d.haze : 0.0f,
		      0, 0);
	gl->Uniform1f(v->u[U_EXAG], v->d.exaggeration);
	int layers = (view_clipmap_texture(v->cm, VIEW_COLOR) ? 1 : 0) |
		     (view_clipmap_texture(v->cm, VIEW_NORMAL) ? 2 : 0);
	gl->Uniform1i(v->u[U_LAYERS], layers);
	for (int r = 0; r < VIEW_NROLES; r++) {
		gl->ActiveTexture(GL_TEXTURE0 + (GLenum)r);
		gl->BindTexture(GL_TEXTURE_2D_ARRAY, view_clipmap_texture(v->cm, (enum view_role)r));
	}
}

int view_frame(struct view *v, const struct view_camera *cam, double now_s,
	       struct view_frame_stats *st)
{
	const struct gl *gl = v->gl;
	double t0 = now_ms();
	struct view_frame_stats s = { .lfirst = -1, .llast = -1 };
	struct view_clipmap_stats cs0, cs1;
	view_clipmap_get_stats(v->cm, &cs0);

	/* Camera: height above the terrain as far as the clipmap knows it. */
	v->last = *cam;
	v->last.width = v->d.width;
	v->last.height = v->d.height;
	double ground = 0;
	view_clipmap_ground(v->cm, cam->lon, cam->lat, &ground);
	double agl = fmax(cam->alt, 0.05);
	v->last.alt = ground * v->d.exaggeration + agl;
	s.ground = ground;
	s.agl = agl;
	s.alt = v->last.alt;

	int lmin, lmax;
	view_level_range(&v->body, &v->last, agl, v->d.n_phi, v->max_level, &lmin, &lmax);
	s.lmin = lmin;
	s.lmax = lmax;
	double cap = view_horizon_cap(&v->body, v->last.alt);

	/* Algorithm 1, lines 2-9: a new focus sends a new want-set. */
	bool changed = !v->sent_once;
	set_targets(v, lmin, lmax, &changed);
	int rc = view_clipmap_receive(v->cm);
	if (rc < 0)
		return rc;
	s.tiles_received = rc;
	if (changed) {
		size_t n = view_clipmap_wants(v->cm, !v->d.no_prefetch, v->wants, MAX_WANTS);
		struct view_focus f = { cam->lon, cam->lat, v->last.alt, { 0, 0, 0 } };
		rc = v->src->ops->want(v->src, v->wants, n, &f);
		if (rc < 0)
			return rc;
		v->sent_once = true;
		s.wants_sent = n ? n : 1;
	}

	/* Lines 10-26: coarse → fine, ring while the next level can be drawn, else disk. */
	gl->BindFramebuffer(GL_FRAMEBUFFER, v->fbo);
	gl->Viewport(0, 0, v->d.width, v->d.height);
	float bg[3];
	if (v->d.background_set) {
		memcpy(bg, v->d.background, sizeof bg);
	} else {
		/* space, turning to a pale blue sky inside the atmosphere (none without air) */
		double sky = v->d.haze > 0 ? exp(-agl / 35e3) : 0;
		bg[0] = (float)(0.01 + 0.52 * sky);
		bg[1] = (float)(0.01 + 0.68 * sky);
		bg[2] = (float)(0.03 + 0.87 * sky);
	}
	for (int i = 0; i < 3; i++)
		v->bg[i] = (unsigned char)lrintf(fminf(fmaxf(bg[i], 0), 1) * 255);
	v->bg[3] = 255;
	gl->ClearColor(v->bg[0] / 255.0f, v->bg[1] / 255.0f, v->bg[2] / 255.0f, 1);
	if (v->reversed) {
		gl->ClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
		gl->ClearDepth(0.0);
		gl->DepthFunc(GL_GREATER);
	} else {
		gl->ClearDepth(1.0);
		gl->DepthFunc(GL_LESS);
	}
	gl->Enable(GL_DEPTH_TEST);
	gl->DepthMask(GL_TRUE);
	gl->Clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
	gl->UseProgram(v->prog);
	gl->BindVertexArray(v->vao);
	common_uniforms(v, agl, cap);

	int first = -1;
	for (int j = lmin; j >= 0 && first < 0; j--)
		if (usable(v, j, fmin(view_ring_radius(j), cap)))
			first = j;
	bool complete = first == lmin;
	for (int i = first; i >= 0 && i <= lmax; i++) {
		if (!v->was_usable[i]) {
			v->was_usable[i] = true;
			v->ready_since[i] = now_s;
		}
		int next = i + 1;
		bool more = next <= lmax &&
			    (v->d.budget_ms <= 0 || now_ms() - t0 < v->d.budget_ms) &&
			    usable(v, next, fmin(view_ring_radius(next), cap));
		double fade = 1;
		if (v->d.fade_s > 0 && i != first)
			fade = fmin(1, (now_s - v->ready_since[i]) / v->d.fade_s);
		s.triangles += draw_level(v, i, more, i == first, fade, cap, &s.triangles_culled);
		if (s.lfirst < 0)
			s.lfirst = i;
		s.llast = i;
		if (!more)
			break;
	}
	for (int l = (s.llast >= 0 ? s.llast + 1 : 0); l < v->nlevels; l++)
		v->was_usable[l] = false;
	if (s.llast != lmax)
		complete = false;
	for (int l = lmin; l <= lmax && complete; l++) {
		const struct grid_quad *h = view_clipmap_held(v->cm, l);
		const struct grid_quad *t = view_clipmap_target_of(v->cm, l);
		complete = h && t && grid_quad_equal(h, t);
	}
	s.complete = complete;
	gl->BindVertexArray(0);
	gl->Finish();
	view_clipmap_get_stats(v->cm, &cs1);
	s.bytes_uploaded = cs1.bytes_uploaded - cs0.bytes_uploaded;
	s.cpu_ms = now_ms() - t0;
	GLenum e = gl->GetError();
	if (st)
		*st = s;
	return e == GL_NO_ERROR ? 0 : -EIO;
}

int view_frame_complete(struct view *v, const struct view_camera *c, double timeout_s,
			struct view_frame_stats *st, int *frames)
{
	double t0 = now_ms();
	struct view_frame_stats s = { 0 };
	int n = 0, rc = 0;
	for (;;) {
		rc = view_frame(v, c, 0, &s);
		n++;
		if (rc < 0)
			break;
		/* The frame used the ground height known before its uploads: settled when the
		 * uploads did not change it. */
		double g = 0;
		view_clipmap_ground(v->cm, c->lon, c->lat, &g);
		bool settled = g == s.ground;
		if (s.complete && settled)
			break;
		double left = timeout_s * 1e3 - (now_ms() - t0);
		if (left <= 0) {
			rc = -ETIMEDOUT;
			break;
		}
		/* Nothing new yet: sleep until a tile arrives (the interactive loop never does). */
		if (!s.complete && s.tiles_received == 0 && !s.wants_sent)
			v->src->ops->wait(v->src, (int)fmin(left, 200));
	}
	if (st)
		*st = s;
	if (frames)
		*frames = n;
	return rc;
}

static void free_fbo(struct view *v)
{
	const struct gl *gl = v->gl;
	if (v->fbo)
		gl->DeleteFramebuffers(1, &v->fbo);
	if (v->color_tex)
		gl->DeleteTextures(1, &v->color_tex);
	if (v->depth_tex)
		gl->DeleteTextures(1, &v->depth_tex);
	v->fbo = v->color_tex = v->depth_tex = 0;
}

int view_resize(struct view *v, int width, int height, char err[256])
{
	if (width < 1 || height < 1 || width > 16384 || height > 16384) {
		snprintf(err, 256, "framebuffer %dx%d: out of range", width, height);
		return -EINVAL;
	}
	if (width == v->d.width && height == v->d.height && v->fbo)
		return 0;
	free_fbo(v);
	v->d.width = width;
	v->d.height = height;
	return build_fbo(v, err);
}

unsigned view_framebuffer(const struct view *v) { return v->fbo; }

void view_last_camera(const struct view *v, struct view_camera *out) { *out = v->last; }

int view_read_rgba(struct view *v, unsigned char *out)
{
	const struct gl *gl = v->gl;
	int w = v->d.width, h = v->d.height;
	gl->BindFramebuffer(GL_FRAMEBUFFER, v->fbo);
	gl->PixelStorei(GL_PACK_ALIGNMENT, 1);
	gl->ReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, out);
	/* GL's first row is the bottom one. */
	size_t row = (size_t)w * 4;
	unsigned char *tmp = xmalloc(row);
	for (int y = 0; y < h / 2; y++) {
		memcpy(tmp, out + (size_t)y * row, row);
		memcpy(out + (size_t)y * row, out + (size_t)(h - 1 - y) * row, row);
		memcpy(out + (size_t)(h - 1 - y) * row, tmp, row);
	}
	free(tmp);
	return 0;
}

struct view_clipmap *view_get_clipmap(struct view *v) { return v->cm; }
const struct view_body *view_get_body(const struct view *v) { return &v->body; }
void view_background_rgba(const struct view *v, unsigned char out[4]) { memcpy(out, v->bg, 4); }
