/* view — see view.h. Design notes:
 * - Geometry: NR = nlevels rings of m circles of n vertices (θ̃ geometric within a ring,
 *   halving per level, seed 000 §3.4) plus the nadir vertex; uploaded once. A level drawn as
 *   a full disk uses its ring, the two finer rings (still finer than its texels need) and a
 *   fan to the nadir; a level drawn where finer ones are missing (after a jump, a late tile)
 *   takes their rings too, so the ground keeps its shape and the picture has no hole.
 * - Plan (seed 003 Algorithm 1): every level whose texture covers its ring is drawn each
 *   frame; the time budget counts the frame's texture uploads and only holds back further
 *   uploads of new quads (taking tiles, drawing: not the plan's to stop).
 * - Detail: a ring's heights come from its own level, its colour and normals from the finest
 *   level up to CLIPMAP_DETAIL finer whose window (CLIPMAP_WINDOW_TILES tiles wide) covers it — a
 *   texel about 2 pixels (by area) across the ring, where its own level's would be 4–8. Where that
 *   level is not resident yet (after a jump), the next coarser one that is.
 * - Culling: each ring is split into an outer and an inner part (below), each part (and the
 *   fan) into NSEC sectors of φ̃, each one index range (ring, part, sector, circle). Per frame
 *   the CPU tests each sector's bounds (view_sector_visible: its θ̃ × φ̃ patch at the height
 *   range the two levels' slices hold within the ring's disk — not the whole window, ten
 *   times wider —, placed in doubles as the shader does, inflated by the patch's bulge)
 *   against the frustum's side planes, the plane behind the camera and the horizon cap, and
 *   draws the visible ranges, contiguous ones merged. Then the horizon (near the ground
 *   most levels lie behind the nearer ground): as each level is drawn, fine → coarse, each
 *   of its ring's cells (HSUB_PH per sector × HSUB_TH across the ring) gives the least
 *   elevation its lowest ground (its texels, on the CPU) can be seen at; the ground being
 *   continuous from the nadir out, every line of sight in those directions meets ground at
 *   least that high before the ring's edge, so a coarser sector whose highest ground (its
 *   own texels) stays below the horizon of its directions is hidden and not drawn. Per
 *   level, cached while the camera and its heights stay. The triangle order is the same
 *   with culling off, so the pixels are too (test_view_gl compares them).
 * - Order: front to back, so that the depth test rejects hidden ground before it is shaded
 *   (llvmpipe tests depth first): levels fine → coarse, and within a sector the circles near
 *   → far (a hill's near side before what it hides), each quad's triangles starting with the
 *   circle the previous row shared (llvmpipe's vertex cache then reuses it).
 * - Blending: over the outer part of a ring (from θ̃ = 2^(−j0/m)·R, about 0.74 R, to 0.95 R)
 *   the height, colour and normal fade to the next coarser level, reaching it on the boundary,
 *   so neighbouring rings share their boundary vertices (no cracks) and no level boundary
 *   pops. The inner part shows the fine level alone and is drawn by a program variant that
 *   samples one level: llvmpipe executes both sides of every branch, so work a pixel does not
 *   need is compiled out rather than skipped (variants: blend, per-fragment lon/lat near the
 *   poles, haze, exaggeration, which layers exist, a sea, unlit — compiled on first use).
 * - The look (the planet's, view_source.h): the air sets the sky's colour and the haze's
 *   extinction (air_init); a sea lifts the ground below it to the water's surface in the
 *   shader, so culling bounds and the camera's ground are taken at that surface too. The
 *   surface is sea_level plus the planet's geoid lattice where it has one (sea_init: a small
 *   texture the vertex shader samples); with a sea mask, ground whose colour's alpha is under
 *   255 is never sea (the shaders, and the camera's ground through the clipmap's copy of that
 *   alpha).
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

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/xalloc.h"

#include "terrain_frag.h"
#include "terrain_vert.h"

#define DEG (M_PI / 180.0)
#define MAX_WANTS 4096

enum {
	U_VP, U_LAT, U_BODY, U_A, U_CAP, U_BLEND, U_T, U_PF, U_VF, U_SF, U_PC, U_VC, U_SC, U_DF,
	U_DVF, U_DSF, U_DC, U_DVC, U_DSC, U_FADE, U_HEIGHT, U_NORMAL, U_COLOR, U_SUN, U_HAZE,
	U_EXAG, U_SEA, U_SEAG, U_SEAGRID, U_SEAMASK, U_COUNT
};
static const char *const uniform_names[U_COUNT] = {
	"u_vp",	 "u_lat", "u_body", "u_a",   "u_cap",	 "u_blend",  "u_T",	"u_pf",
	"u_vf",	 "u_sf",  "u_pc",   "u_vc",  "u_sc",	 "u_df",     "u_dvf",	"u_dsf",
	"u_dc",	 "u_dvc", "u_dsc",  "u_fade", "u_height", "u_normal", "u_color", "u_sun",
	"u_haze", "u_exag", "u_sea",  "u_seag",  "u_seagrid", "u_seamask",
};

/* Horizon culling's per-level results, kept while the camera and the heights stay. */
struct hcache {
	bool valid;
	double key[9];	      /* camera lon, lat, alt, heading, pitch, fov, frame cap, last,
			       * whether it is an occluder */
	uint64_t hver[2];     /* the two levels' height versions */
	int c;		      /* the level it blends towards */
	double hz[32 * 4];    /* its ring's contribution per subsector (-∞: none) */
	double hi[3][32];     /* per sector, its highest ground over its ring's outer part, inner
			       * part, every ring it draws (NAN: not yet) */
};

/* Program variants: the shaders' #defines (see their headers). */
enum {
	VAR_BLEND = 1, VAR_GEO_FRAG = 2, VAR_HAZE = 4, VAR_EXAG = 8, VAR_COLOR = 16, VAR_NORMAL = 32,
	VAR_SEA = 64, VAR_UNLIT = 128, NVARIANT = 256
};
static const char *const variant_names[] = { "BLEND", "GEO_FRAG", "HAZE", "EXAG",
					     "COLOR", "NORMAL",	  "SEA",  "UNLIT" };

/* Horizon culling's cells: subsectors per sector, cells across a ring. */
#define HSUB_PH 4
#define HSUB_TH 4
#define HORIZON_LEVELS 8
#define MESH_HALF_ABOVE 0.25 /* × the planet's radius: the rings at half density above */
#define BLEND_END 0.95 /* the coarse level fully shown from here (× the ring's outer θ̃) */
/* A camera step longer than this many heights above the ground between two frames is a jump,
 * not flight (view_fly moves about one height a frame at most). */
#define JUMP_HEIGHTS 10.0

struct frame_uniforms {
	float vp[16], lat[3], body[4], a, cap, sun[3], haze[4], sea[2], seagrid[3], seamask;
};

struct program {
	unsigned id;
	int u[U_COUNT];
	uint64_t frame; /* the frame whose common uniforms it holds */
};

/* The air the frames are drawn through (from the planet's look and view_desc.haze). */
struct air {
	bool on;
	double height;	/* scale height, metres */
	float beta[3];	/* extinction per metre of sea-level air, red, green, blue */
	float sky[3];	/* the sky's colour at the ground (the clear colour's encoding) */
};

/* The rings' index buffer at one density: every `step`-th circle and step around. At the
 * full density a ring cell is about a pixel at the nadir of the finest level (view_levels);
 * high above a planet, where no relief reaches a pixel, half the density draws the same
 * picture with a quarter of the triangles (view_frame picks it per frame, MESH_HALF_ABOVE). */
struct mesh {
	int step;	   /* 1: every circle and step; 2: every other one */
	int j0;		   /* the outer part's rows: j0 rounded up to a multiple of step */
	size_t *sec_first; /* ring i part p sector s: from sec_first[(2i+p)·nsec+s] to the next */
	size_t *fan_first; /* per circle-boundary k·m (k = 1..NR), (n / step)·3 indices each */
};

struct view {
	const struct gl *gl;
	struct view_source *src;
	struct view_desc d;
	struct air air;
	/* The sea's surface: sea_level, plus the planet's geoid lattice where it has one (a
	 * GL_TEXTURE_2D of metres on unit SEA_UNIT; 1 × 1 texel of 0 without), and the lowest and
	 * highest it gets, metres. */
	unsigned sea_tex;
	double sea_lo, sea_hi;
	struct view_body body;
	struct view_clipmap *cm;
	int nlevels, max_level;
	uint32_t T, S; /* tile size, texture window size */
	/* geometry */
	unsigned vao, vbo, ibo;
	int nsec;		 /* sectors per ring part */
	int j0;			 /* rows 0..j0-1 of a ring (from its outer edge) form its outer part */
	struct mesh mesh[2];	 /* the rings' triangles: every vertex, and every other one */
	int nmesh;		 /* 2 where the rings can be halved (even counts), else 1 */
	const struct mesh *cur_mesh; /* this frame's */
	int mesh_mode;		 /* view_set_mesh: 0 by height, 1 full, 2 half */
	bool cull;
	/* programs, by variant; the one in use */
	struct program prog[NVARIANT];
	struct program *cur;
	uint64_t frame_no;
	int frame_bits; /* this frame's variant bits that every level shares */
	int *drawn;	/* this frame's levels drawn, coarse → fine */
	int *detail;	/* per level drawn: the level its colour and normals come from */
	double last_agl; /* the last frame's camera height above the ground */
	double *floor;	/* per level: lowest ground it and the finer levels hold (INFINITY: unknown) */
	double *fade;	/* per level: this frame's fade-in (1: fully shown) */
	double *horizon; /* per subsector (HSUB_PH per sector), this frame: the least elevation at which the ground drawn
			  * so far (the finer levels, nearer) meets each line of sight in its
			  * directions (-∞: none known); what lies lower behind it is hidden */
	double frame_cap; /* this frame's horizon cap: no vertex lies beyond it */
	int cur_i, cur_c; /* the level being drawn and the one it blends towards */
	int cur_last;	  /* and the finest ring it draws */
	bool need[32];	  /* this frame: sector s or a neighbour can be seen */
	struct hcache *hc; /* per level: its part of the horizon and its sectors' highest ground,
			    * for the camera and heights they were found for */
	int idle_tiles; /* tiles taken by view_idle since the last frame */
	struct frame_uniforms fu;
	/* framebuffer */
	unsigned fbo, color_tex, depth_tex;
	bool reversed;
	/* state */
	struct view_want *wants;
	bool sent_once;
	int color_next; /* the colour layer view_set_color_layer asked for, switched to at the
			 * next frame (-1: none): one switch per want-set sent, so the daemon
			 * sees every tile dropped by a switch leave the set before it is wanted
			 * again */
	bool *was_usable;
	double *ready_since;
	struct view_camera last;
	unsigned char bg[4];
};

static unsigned compile(const struct gl *gl, GLenum type, const char *src, int bits,
			const char *name, char err[256])
{
	/* The defines go after the #version line, which must come first. */
	char head[256];
	int n = snprintf(head, sizeof head, "#version 330 core\n");
	for (int b = 0; b < (int)(sizeof variant_names / sizeof variant_names[0]); b++)
		n += snprintf(head + n, sizeof head - (size_t)n, "#define %s %d\n", variant_names[b],
			      (bits >> b) & 1);
	const char *body = strchr(src, '\n');
	const char *parts[2] = { head, body ? body + 1 : src };
	unsigned s = gl->CreateShader(type);
	gl->ShaderSource(s, 2, parts, NULL);
	gl->CompileShader(s);
	int ok = 0;
	gl->GetShaderiv(s, GL_COMPILE_STATUS, &ok);
	if (!ok) {
		char log[200] = "";
		gl->GetShaderInfoLog(s, sizeof log, NULL, log);
		err_set(err, "%s (variant %d): %s", name, bits, log);
		gl->DeleteShader(s);
		return 0;
	}
	return s;
}

/* The program of variant bits, compiled and linked on first use. */
static struct program *get_program(struct view *v, int bits, char err[256])
{
	struct program *p = &v->prog[bits];
	if (p->id)
		return p;
	const struct gl *gl = v->gl;
	unsigned vs = compile(gl, GL_VERTEX_SHADER, terrain_vert_src, bits, "terrain.vert", err);
	if (!vs)
		return NULL;
	unsigned fs = compile(gl, GL_FRAGMENT_SHADER, terrain_frag_src, bits, "terrain.frag", err);
	if (!fs) {
		gl->DeleteShader(vs);
		return NULL;
	}
	unsigned id = gl->CreateProgram();
	gl->AttachShader(id, vs);
	gl->AttachShader(id, fs);
	gl->LinkProgram(id);
	gl->DeleteShader(vs);
	gl->DeleteShader(fs);
	int ok = 0;
	gl->GetProgramiv(id, GL_LINK_STATUS, &ok);
	if (!ok) {
		char log[200] = "";
		gl->GetProgramInfoLog(id, sizeof log, NULL, log);
		err_set(err, "terrain program (variant %d): %s", bits, log);
		gl->DeleteProgram(id);
		return NULL;
	}
	p->id = id;
	for (int i = 0; i < U_COUNT; i++)
		p->u[i] = gl->GetUniformLocation(id, uniform_names[i]);
	p->frame = 0;
	return p;
}

/* θ̃ of circle c (c = ring·m + j). */
static double circle_theta(int c, int m)
{
	int i = c / m, j = c % m;
	double r0 = clipmap_ring_radius(i), r1 = clipmap_ring_radius(i + 1);
	return r0 * pow(r1 / r0, (double)j / m);
}

/* The first φ̃ step of sector s. */
static int sector_k(const struct view *v, int s) { return s * v->d.n_phi / v->nsec; }

/* Appends the rings' triangles at density 1/step to idx[*q...]: for each ring's two parts
 * and each sector, its cells from the inner circle out... as the full mesh, on the circles
 * and steps that are multiples of step (the vertex buffer is shared). */
static void build_mesh(struct view *v, struct mesh *me, int step, uint32_t *idx, size_t *q)
{
	int n = v->d.n_phi, m = v->d.m_rings, NR = v->nlevels;
	uint32_t centre = (uint32_t)((NR * m + 1) * n);
	me->step = step;
	me->j0 = (v->j0 + step - 1) / step * step;
	me->sec_first = xcalloc((size_t)NR * 2 * v->nsec + 1, sizeof *me->sec_first);
	me->fan_first = xcalloc((size_t)NR + 1, sizeof *me->fan_first);
	for (int ip = 0; ip < NR * 2; ip++)
		for (int sec = 0; sec < v->nsec; sec++) {
			int i = ip / 2, c0 = i * m + (ip % 2 ? me->j0 : 0);
			int c1 = ip % 2 ? (i + 1) * m : i * m + me->j0;
			me->sec_first[ip * v->nsec + sec] = *q;
			for (int c = c1 - step; c >= c0; c -= step)
				for (int k = sector_k(v, sec); k < sector_k(v, sec + 1); k += step) {
					uint32_t a = (uint32_t)(c * n + k);
					uint32_t b = (uint32_t)(c * n + (k + step) % n);
					uint32_t a2 = a + (uint32_t)(step * n), b2 = b + (uint32_t)(step * n);
					uint32_t t[6] = { b2, a2, a, b2, a, b };
					memcpy(idx + *q, t, sizeof t);
					*q += 6;
				}
		}
	me->sec_first[NR * 2 * v->nsec] = *q;
	for (int k1 = 1; k1 <= NR; k1++) {
		me->fan_first[k1] = *q;
		int c = k1 * m;
		for (int k = 0; k < n; k += step) {
			idx[(*q)++] = (uint32_t)(c * n + k);
			idx[(*q)++] = (uint32_t)(c * n + (k + step) % n);
			idx[(*q)++] = centre;
		}
	}
}

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
	size_t full = (size_t)NR * m * n * 6 + (size_t)NR * n * 3;
	size_t nidx = full + full / 2; /* and the half mesh: a quarter of the cells, half the fans */
	uint32_t *idx = xmalloc(nidx * sizeof *idx);
	v->nsec = n < 32 ? n : 32;
	v->j0 = m - (m * 9) / 16; /* the inner ~56 % of the rows show the fine level alone */
	if (v->j0 < 1)
		v->j0 = 1;
	size_t q = 0;
	v->nmesh = m % 2 == 0 && (n / v->nsec) % 2 == 0 && n % v->nsec == 0 ? 2 : 1;
	for (int h = 0; h < v->nmesh; h++)
		build_mesh(v, &v->mesh[h], h + 1, idx, &q);
	v->cur_mesh = &v->mesh[0];
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
		err_set(err, "framebuffer %dx%d incomplete (0x%x)", v->d.width, v->d.height, st);
		return -EINVAL;
	}
	return 0;
}

/* Earth's air: what --haze gives a planet that has none of its own. */
static const struct view_look earth_air = { .air_density = 1, .air_height = 8000,
					    .air_color = { 133, 173, 222 } };

/* The texture unit of the sea's lattice (the layers' textures take 0 .. VIEW_NROLES − 1). */
#define SEA_UNIT VIEW_NROLES

/* The sea's surface lattice as a texture (metres above sea_level; a texel of 0 without one),
 * and its range. Longitude wraps, latitude clamps at the poles. */
static void sea_init(struct view *v, const struct view_look *look)
{
	const struct gl *gl = v->gl;
	const struct sea_grid *g = &look->sea_grid;
	double lo = 0, hi = 0;
	sea_grid_range(g, &lo, &hi);
	v->sea_lo = look->sea_level + lo;
	v->sea_hi = look->sea_level + hi;
	int rows = g->rows ? g->rows : 1, cols = g->rows ? g->cols : 1;
	float *m = xmalloc((size_t)rows * cols * sizeof *m);
	for (size_t i = 0; i < (size_t)rows * cols; i++)
		m[i] = g->rows ? g->dm[i] / 10.0f : 0.0f;
	gl->GenTextures(1, &v->sea_tex);
	gl->ActiveTexture(GL_TEXTURE0 + SEA_UNIT);
	gl->BindTexture(GL_TEXTURE_2D, v->sea_tex);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_REPEAT);
	gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
	gl->TexImage2D(GL_TEXTURE_2D, 0, GL_R32F, cols, rows, 0, GL_RED, GL_FLOAT, m);
	gl->ActiveTexture(GL_TEXTURE0);
	free(m);
}

/* The sea's surface at (lon, lat) degrees, metres above the ellipsoid. */
static double sea_height(const struct view *v, double lon, double lat)
{
	const struct view_look *look = &v->src->planet.look;
	return look->sea_level + sea_grid_at(&look->sea_grid, lat, lon);
}

/* The air from the planet's look; haze (view_desc) > 0 overrides its density, < 0 removes it.
 * The extinction's spectrum follows the cube of the sky's colour: Earth's (133, 173, 222)
 * gives Rayleigh's λ⁻⁴ blue plus a little grey Mie (7.4, 16.4, 34.6 µ/m, 58.4 in all at
 * density 1, as the viewer always drew it); Mars' butterscotch a red-heavy dust haze. The
 * light the air scatters into a ray is sunlight × (1 − transmittance), so the haze takes the
 * colour of the extinction. */
static void air_init(struct air *air, const struct view_look *look, float haze)
{
	*air = (struct air){ .on = false };
	if (haze < 0)
		return;
	double density = look->air_density;
	if (!(density > 0 && look->air_height > 0)) {
		if (haze == 0)
			return;
		look = &earth_air;
	}
	if (haze > 0)
		density = haze;
	double c3[3], sum = 0;
	for (int i = 0; i < 3; i++) {
		double c = look->air_color[i] / 255.0;
		c3[i] = c * c * c + 1e-4;
		sum += c3[i];
		air->sky[i] = (float)c;
	}
	for (int i = 0; i < 3; i++)
		air->beta[i] = (float)(0.45 * density * 58.4e-6 * c3[i] / sum);
	air->height = look->air_height;
	air->on = true;
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
		v->d.sun_az = VIEW_SUN_AZ;
		v->d.sun_el = VIEW_SUN_EL;
	}
	if (!(v->d.exaggeration > 0))
		v->d.exaggeration = 1;
	const struct view_planet *p = &src->planet;
	air_init(&v->air, &p->look, v->d.haze);
	sea_init(v, &p->look);
	view_body_init(&v->body, p->a, p->f);
	v->body.hmin *= v->d.exaggeration;
	v->body.hmax *= v->d.exaggeration;
	v->max_level = p->max_level < GRID_MAX_LEVEL ? p->max_level : GRID_MAX_LEVEL;
	v->nlevels = v->max_level + 1;
	v->T = p->tile_size;
	v->S = CLIPMAP_WINDOW_TILES * v->T;
	v->reversed = gl->ClipControl != NULL;
	const char *nc = getenv("CLIPMAP_NO_CULL");
	v->cull = !v->d.no_cull && !(nc && strcmp(nc, "1") == 0);
	v->wants = xmalloc(MAX_WANTS * sizeof *v->wants);
	v->color_next = -1;
	v->was_usable = xcalloc((size_t)v->nlevels, sizeof *v->was_usable);
	v->ready_since = xcalloc((size_t)v->nlevels, sizeof *v->ready_since);
	v->floor = xcalloc((size_t)v->nlevels, sizeof *v->floor);
	v->fade = xcalloc((size_t)v->nlevels, sizeof *v->fade);
	v->horizon = xcalloc(32 * HSUB_PH, sizeof *v->horizon); /* nsec ≤ 32 */
	v->hc = xcalloc((size_t)v->nlevels, sizeof *v->hc);
	v->drawn = xcalloc((size_t)v->nlevels, sizeof *v->drawn);
	v->detail = xcalloc((size_t)v->nlevels, sizeof *v->detail);
	/* normals made from the heights (view_desc.normals, view_clipmap), or fetched */
	bool derive = d->normals == VIEW_NORMALS_DERIVE ||
		      (d->normals == VIEW_NORMALS_AUTO && view_clipmap_can_derive(p));
	int rc = view_clipmap_create_layer(gl, src, v->nlevels, d->color_layer, !derive,
					   &v->cm, err);
	if (rc == 0)
		view_clipmap_keep_alpha(v->cm, p->look.sea_mask);
	if (rc == 0)
		/* every feature (lit): fail early */
		rc = get_program(v, (NVARIANT - 1) & ~VAR_UNLIT, err) ? 0 : -EINVAL;
	if (rc == 0) {
		build_geometry(v);
		rc = build_fbo(v, err);
	}
	if (rc == 0) {
		GLenum e = gl->GetError();
		if (e != GL_NO_ERROR) {
			err_set(err, "view setup: GL error 0x%x", e);
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
	if (v->sea_tex)
		gl->DeleteTextures(1, &v->sea_tex);
	for (int i = 0; i < NVARIANT; i++)
		if (v->prog[i].id)
			gl->DeleteProgram(v->prog[i].id);
	if (v->vao)
		gl->DeleteVertexArrays(1, &v->vao);
	if (v->vbo)
		gl->DeleteBuffers(1, &v->vbo);
	if (v->ibo)
		gl->DeleteBuffers(1, &v->ibo);
	free_fbo(v);
	for (int h = 0; h < v->nmesh; h++) {
		free(v->mesh[h].sec_first);
		free(v->mesh[h].fan_first);
	}
	free(v->wants);
	free(v->was_usable);
	free(v->ready_since);
	free(v->floor);
	free(v->fade);
	free(v->horizon);
	free(v->hc);
	free(v->drawn);
	free(v->detail);
	free(v);
}

/* The frame's uploads against its time budget (Algorithm 1's time limit): what they have
 * taken, not the whole frame — taking the tiles (a network source decodes them) and drawing
 * are not the plan's to limit, and the first upload of a frame always goes ahead. */
struct uploads {
	double spent_ms; /* in view_clipmap_update this frame */
	int done;	 /* levels uploaded this frame */
};

static bool may_upload(const struct view *v, const struct uploads *u)
{
	return v->d.budget_ms <= 0 || u->spent_ms < v->d.budget_ms;
}

/* Whether level l can be drawn out to angle r: its texture holds a window that covers it.
 * What is resident is drawable whatever the time; only copying in the level's new quad
 * (when complete) waits for the budget. */
static bool usable(struct view *v, int l, double r, struct uploads *u)
{
	const struct grid_quad *t = view_clipmap_target_of(v->cm, l);
	const struct grid_quad *h = view_clipmap_held(v->cm, l);
	if (t && (!(h && grid_quad_equal(h, t)) || view_clipmap_color_stale(v->cm, l)) &&
	    may_upload(v, u)) {
		double t0 = clock_now_ms();
		if (view_clipmap_update(v->cm, l) == 1)
			u->done++;
		u->spent_ms += clock_now_ms() - t0;
	}
	h = view_clipmap_held(v->cm, l);
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

void view_set_mesh(struct view *v, int mode) { v->mesh_mode = mode; }

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

static bool cell_range(struct view *v, int i, int c, double th0, double th1, double ph0,
		       double ph1, double *lo_out, double *hi_out);

/* Whether the ground of sector s over θ̃ ∈ [th0, th1], no higher than b->hmax, lies below the
 * horizon the finer levels drew in its directions (its subsectors' and the two next to them:
 * the ellipsoid turns a ring point's azimuth from its φ̃ by up to ~0.4°), so behind their
 * ground. */
static bool occluded(struct view *v, const struct view_body *b, double th0, double th1,
		     int s)
{
	int ns = v->nsec * HSUB_PH;
	double hz = INFINITY;
	for (int q = s * HSUB_PH - 1; q <= (s + 1) * HSUB_PH; q++)
		hz = fmin(hz, v->horizon[(q + ns) % ns]);
	th1 = fmin(th1, v->frame_cap);
	if (!(hz > -M_PI / 2) || th0 >= th1)
		return false;
	double ph0 = 2 * M_PI * sector_k(v, s) / v->d.n_phi;
	double ph1 = 2 * M_PI * sector_k(v, s + 1) / v->d.n_phi;
	if (view_sector_elev_max(b, &v->last, th0, th1, ph0, ph1, b->hmax) < hz)
		return true;
	/* the sector's own highest ground, not the ring's: over the part of the level's ring
	 * (0: outer, 1: inner) the sector spans, or every ring it draws (2) */
	double r0 = clipmap_ring_radius(v->cur_i + 1);
	int part = th0 < r0 * (1 - 1e-9) ? 2 : th0 > r0 * (1 + 1e-9) ? 0 : 1;
	double *hi = &v->hc[v->cur_i].hi[part][s];
	if (isnan(*hi)) {
		double lo, r1 = fmin(clipmap_ring_radius(v->cur_i), v->frame_cap);
		if (part == 2)
			r0 = clipmap_ring_radius(v->cur_last + 1);
		if (part < 2) {
			r0 = th0;
			r1 = fmin(th1, r1);
		}
		if (!(r0 < r1) || !cell_range(v, v->cur_i, v->cur_c, r0, r1, ph0, ph1, &lo, hi))
			*hi = INFINITY;
	}
	return view_sector_elev_max(b, &v->last, th0, th1, ph0, ph1, fmin(*hi, b->hmax)) < hz;
}

/* Draws sector s of the geometry over θ̃ ∈ [th0, th1] (indices [first, first + count)) if
 * visible; counts its indices in *drawn or *culled. */
static void draw_sector(struct view *v, const struct view_body *b, struct ranges *r, double th0,
			double th1, int s, size_t first, size_t count, double cap, uint64_t *drawn,
			uint64_t *culled)
{
	double ph0 = 2 * M_PI * sector_k(v, s) / v->d.n_phi;
	double ph1 = 2 * M_PI * sector_k(v, s + 1) / v->d.n_phi;
	if (v->cull && (!view_sector_visible(b, &v->last, th0, th1, ph0, ph1, cap) ||
			occluded(v, b, th0, th1, s))) {
		*culled += count;
		return;
	}
	ranges_add(r, first, count);
	*drawn += count;
}

/* The heights level l's slice draws within angle r of the camera's nadir (r < 0: the whole
 * slice): what it holds there, lifted to the water's surface where the planet has a sea (the
 * vertex shader draws the sea there, not its floor). Returns 0, or -ENOENT before its first
 * upload. */
static int drawn_range_near(struct view *v, int l, double r, double *lo, double *hi)
{
	int rc = r < 0 ? view_clipmap_height_range(v->cm, l, lo, hi)
		       : view_clipmap_height_range_near(v->cm, l, v->last.lon, v->last.lat, r, lo,
							hi);
	if (rc == 0 && v->src->planet.look.sea) {
		*lo = fmax(*lo, v->sea_lo);
		*hi = fmax(*hi, v->sea_hi);
	}
	return rc;
}

/* The same over the whole slice. */
static int drawn_range(struct view *v, int l, double *lo, double *hi)
{
	return drawn_range_near(v, l, -1, lo, hi);
}

/* Whether the ground levels i and c draw, and the levels their colour comes from, lies
 * above the sea everywhere their slices hold it: the one-level program without water does. */
static bool dry(struct view *v, int i, int c)
{
	const int ls[4] = { i, c, v->detail[i], v->detail[c] };
	double sea = v->sea_hi;
	for (int k = 0; k < 4; k++) {
		double lo, hi;
		if (view_clipmap_height_range(v->cm, ls[k], &lo, &hi) != 0 || !(lo > sea))
			return false;
	}
	return true;
}

/* Binds the program of variant bits for drawing level i (fine) blended towards level c
 * (coarse): the frame's common uniforms on its first use this frame, the levels' always. */
static int bind_program(struct view *v, int bits, int i, int c, float fade)
{
	const struct gl *gl = v->gl;
	char err[256];
	struct program *p = get_program(v, bits, err);
	if (!p)
		return -EINVAL;
	gl->UseProgram(p->id);
	v->cur = p;
	if (p->frame != v->frame_no) {
		const struct frame_uniforms *f = &v->fu;
		gl->UniformMatrix4fv(p->u[U_VP], 1, GL_FALSE, f->vp);
		gl->Uniform3f(p->u[U_LAT], f->lat[0], f->lat[1], f->lat[2]);
		gl->Uniform4fv(p->u[U_BODY], 1, f->body);
		gl->Uniform1f(p->u[U_A], f->a);
		gl->Uniform1f(p->u[U_CAP], f->cap);
		gl->Uniform1f(p->u[U_T], (float)v->S);
		gl->Uniform1i(p->u[U_HEIGHT], 0);
		gl->Uniform1i(p->u[U_NORMAL], 1);
		gl->Uniform1i(p->u[U_COLOR], 2);
		gl->Uniform3f(p->u[U_SUN], f->sun[0], f->sun[1], f->sun[2]);
		gl->Uniform4fv(p->u[U_HAZE], 1, f->haze);
		gl->Uniform1f(p->u[U_EXAG], v->d.exaggeration);
		gl->Uniform2f(p->u[U_SEA], f->sea[0], f->sea[1]);
		gl->Uniform1i(p->u[U_SEAG], SEA_UNIT);
		gl->Uniform3f(p->u[U_SEAGRID], f->seagrid[0], f->seagrid[1], f->seagrid[2]);
		gl->Uniform1f(p->u[U_SEAMASK], f->seamask);
		p->frame = v->frame_no;
	}
	level_uniforms(v, i, p->u[U_PF], p->u[U_VF], p->u[U_SF]);
	level_uniforms(v, c, p->u[U_PC], p->u[U_VC], p->u[U_SC]);
	level_uniforms(v, v->detail[i], p->u[U_DF], p->u[U_DVF], p->u[U_DSF]);
	level_uniforms(v, v->detail[c], p->u[U_DC], p->u[U_DVC], p->u[U_DSC]);
	double R = clipmap_ring_radius(i);
	gl->Uniform3f(p->u[U_BLEND], (float)R, (float)(circle_theta(i * v->d.m_rings + v->j0,
								     v->d.m_rings) / R),
		      (float)BLEND_END);
	gl->Uniform1f(p->u[U_FADE], fade);
	return 0;
}

/* Draws level i over the geometry of rings i..last (more than its own ring where finer
 * levels are missing, down to the next level drawn), and with disk, a fan to the nadir
 * inside ring last; its ring's outer part blends towards level c, the next coarser level
 * drawn (c = i: none). The parts that show the fine level alone go first with the one-level
 * program, then the blended ones; visible sectors only. Returns the triangles drawn (-EINVAL
 * if a program failed). */
static int64_t draw_level(struct view *v, int i, int c, int last, bool disk, double fade,
			  double cap, uint64_t *culled)
{
	const struct gl *gl = v->gl;
	const struct mesh *me = v->cur_mesh;
	int m = v->d.m_rings;
	bool ring = !disk;
	bool fading = disk && fade < 1;
	/* Near a pole the ring's vertices' (lon, lat) cannot be interpolated (the meridian behind
	 * the pole, lon's curvature there): per-fragment lon/lat where the level reaches 0.8 of
	 * the way to the nearer pole. */
	double dpole = M_PI / 2 - fabs(v->last.lat * DEG);
	int bits = v->frame_bits | (fmin(clipmap_ring_radius(i), cap) > 0.8 * dpole ? VAR_GEO_FRAG : 0);
	if ((bits & VAR_SEA) && dry(v, i, c))
		bits &= ~VAR_SEA;
	/* Cull against the heights the two levels' slices hold (the planet's bounds until
	 * both have them), and against the horizon of the lowest ground between the camera and
	 * the level (the slices of this level and every finer one drawn hold all of it): a sphere
	 * through that ground hides whatever of the level lies beyond its horizon. */
	struct view_body b = v->body;
	double lo[2], hi[2];
	double near = fmin(clipmap_ring_radius(i), cap);
	if (drawn_range_near(v, i, near, &lo[0], &hi[0]) == 0 &&
	    drawn_range_near(v, c, near, &lo[1], &hi[1]) == 0) {
		double e = v->d.exaggeration;
		b.hmin = fmin(lo[0], lo[1]) * e;
		b.hmax = fmax(hi[0], hi[1]) * e;
		if (v->floor[i] < INFINITY) {
			/* margins: a sphere of radius a stands in for the ellipsoid's curvature */
			struct view_body occ = b;
			double slack = 100 * e + 1e-5 * b.a;
			occ.hmin = fmin(v->floor[i] * e, b.hmin) - slack;
			occ.hmax = b.hmax + slack;
			cap = fmin(cap, view_horizon_cap(&occ, v->last.alt));
		}
	}
	v->cur_i = i;
	v->cur_c = c;
	v->cur_last = last;
	uint64_t idx = 0, cidx = 0;
	for (int pass = 0; pass < 2; pass++) {
		/* pass 0: one level; pass 1: blended (the outer part of ring i, all when fading) */
		if (pass == 0 && fading)
			continue;
		if (pass == 1 && !fading && c == i)
			break;
		if (bind_program(v, bits | (pass ? VAR_BLEND : 0), i, c, ring ? 1.0f : (float)fade) < 0)
			return -EINVAL;
		struct ranges r = { gl, 0, 0 };
		for (int j = last; j >= i; j--) /* near → far */
			for (int part = 1; part >= 0; part--) {
				bool blended = fading || (j == i && part == 0 && c != i);
				if (blended != (pass == 1))
					continue;
				double split = circle_theta(j * m + me->j0, m);
				double th0 = part ? clipmap_ring_radius(j + 1) : split;
				double th1 = part ? split : clipmap_ring_radius(j);
				const size_t *sf = me->sec_first + (size_t)(2 * j + part) * v->nsec;
				for (int sc = 0; sc < v->nsec; sc++)
					draw_sector(v, &b, &r, th0, th1, sc, sf[sc], sf[sc + 1] - sf[sc],
						    cap, &idx, &cidx);
			}
		if (!ring)
			for (int sc = 0; sc < v->nsec && (pass == 1) == fading; sc++) {
				size_t f = me->fan_first[last + 1] +
					   (size_t)(sector_k(v, sc) / me->step) * 3;
				size_t n = (size_t)((sector_k(v, sc + 1) - sector_k(v, sc)) / me->step) * 3;
				draw_sector(v, &b, &r, 0, clipmap_ring_radius(last + 1), sc, f, n, cap,
					    &idx, &cidx);
			}
		ranges_flush(&r);
	}
	*culled += cidx / 3;
	return (int64_t)(idx / 3);
}

static void set_targets(struct view *v, int lmin, int dmax, bool *changed)
{
	for (int l = 0; l < v->nlevels; l++) {
		if (l != 0 && (l < lmin || l > dmax)) {
			*changed |= view_clipmap_target(v->cm, l, NULL);
			continue;
		}
		const struct grid_quad *cur = view_clipmap_target_of(v->cm, l);
		int lx = clipmap_level_lx(l, v->last.lat, cur ? cur->lx : -1);
		struct grid_quad q;
		grid_window(lx, l, v->T, v->S, v->last.lon, v->last.lat, &q);
		*changed |= view_clipmap_target(v->cm, l, &q);
	}
}

/* The frame's uniforms every program variant shares, and the variant bits that do not
 * depend on the level. */
static void frame_uniforms(struct view *v, double agl, double cap)
{
	struct frame_uniforms *f = &v->fu;
	const struct view_camera *c = &v->last;
	double sl = sin(c->lat * DEG), cl = cos(c->lat * DEG);
	double N = view_body_n(&v->body, sl);
	double near = fmin(fmax(agl * 0.25, 0.01), 1e5);
	double far = sqrt(fmax(0, (v->body.a + c->alt) * (v->body.a + c->alt) -
				       (v->body.a + v->body.hmin) * (v->body.a + v->body.hmin))) +
		     sqrt((v->body.a + v->body.hmax) * (v->body.a + v->body.hmax) -
			  (v->body.a + v->body.hmin) * (v->body.a + v->body.hmin)) +
		     2 * fabs(c->alt);
	view_camera_matrix(c, v->reversed, near, far, f->vp);
	f->lat[0] = (float)sl;
	f->lat[1] = (float)cl;
	f->lat[2] = (float)(c->lat * DEG);
	f->body[0] = (float)(N + c->alt);
	f->body[1] = (float)c->alt;
	f->body[2] = (float)N;
	f->body[3] = (float)v->body.e2;
	f->a = (float)v->body.a;
	f->cap = (float)cap;
	/* The sun: azimuth/elevation at the camera, in its east-north-up frame. */
	double az = v->d.sun_az * DEG, el = v->d.sun_el * DEG;
	f->sun[0] = (float)(sin(az) * cos(el));
	f->sun[1] = (float)(cos(az) * cos(el));
	f->sun[2] = (float)sin(el);
	f->haze[0] = (float)(v->air.height * v->d.exaggeration);
	memcpy(f->haze + 1, v->air.beta, sizeof v->air.beta);
	const struct view_look *look = &v->src->planet.look;
	f->sea[0] = (float)(look->sea_level * v->d.exaggeration);
	f->sea[1] = 1.0f / v->d.exaggeration;
	f->seagrid[0] = look->sea_grid.rows ? look->sea_grid.rows : 1;
	f->seagrid[1] = look->sea_grid.rows ? look->sea_grid.cols : 1;
	f->seagrid[2] = (float)(c->lon * DEG);
	f->seamask = look->sea_mask && view_clipmap_texture(v->cm, VIEW_COLOR) ? 1.0f : 0.0f;
	v->frame_bits = (look->sea ? VAR_SEA : 0) | (v->air.on ? VAR_HAZE : 0) |
			(v->d.unlit ? VAR_UNLIT : 0) |
			(v->d.exaggeration != 1 ? VAR_EXAG : 0) |
			(view_clipmap_texture(v->cm, VIEW_COLOR) ? VAR_COLOR : 0) |
			(view_clipmap_texture(v->cm, VIEW_NORMAL) ? VAR_NORMAL : 0);
	const struct gl *gl = v->gl;
	gl->ActiveTexture(GL_TEXTURE0 + SEA_UNIT);
	gl->BindTexture(GL_TEXTURE_2D, v->sea_tex);
	for (int r = 0; r < VIEW_NROLES; r++) {
		gl->ActiveTexture(GL_TEXTURE0 + (GLenum)r);
		gl->BindTexture(GL_TEXTURE_2D_ARRAY, view_clipmap_texture(v->cm, (enum view_role)r));
	}
}

/* The height of what the camera stands over: the ground as far as the clipmap knows it, or
 * the water above it where the planet has a sea (altitudes are above the sea, not the sea
 * floor). */
static double surface_height(const struct view *v, double lon, double lat)
{
	double ground = 0;
	view_clipmap_ground(v->cm, lon, lat, &ground);
	if (!v->src->planet.look.sea)
		return ground;
	double sea = sea_height(v, lon, lat), a;
	/* a sea mask in the colour's alpha: land below sea level stays land */
	if (v->src->planet.look.sea_mask && view_clipmap_alpha(v->cm, lon, lat, &a) == 0 &&
	    a < 254.5 / 255)
		return ground;
	return ground < sea ? sea : ground;
}

/* One frame's state, passed from step to step by view_frame. */
struct frame {
	double t0;			/* when the frame began, ms */
	struct view_clipmap_stats cs0;	/* the clipmap's counters then */
	double now_s;			/* view_frame's now_s (0: offline, no time) */
	double agl;			/* the camera's height above the ground */
	double cap;			/* the horizon cap at the camera (view_horizon_cap) */
	int lmin, lmax;			/* the levels the camera wants drawn */
	int dmax;			/* and the finest it wants for texture */
	int first, last, nd;		/* levels drawn: first..last, nd of them in v->drawn */
	bool complete;			/* so far: every wanted level drawn */
	struct uploads up;
	struct view_frame_stats s;
};

/* Whether the camera jumped since the last frame (real time only): a step along the ground
 * longer than JUMP_HEIGHTS heights above it, at the greater of the two frames' heights. */
static bool jumped(const struct view *v, const struct view_camera *cam, double agl, double now_s)
{
	if (v->frame_no == 0 || !(now_s > 0))
		return false;
	double p0 = v->last.lat * DEG, p1 = cam->lat * DEG;
	double dl = remainder(cam->lon - v->last.lon, 360.0) * DEG;
	double h = sin((p1 - p0) / 2) * sin((p1 - p0) / 2) +
		   cos(p0) * cos(p1) * sin(dl / 2) * sin(dl / 2);
	double step = 2 * v->body.a * asin(fmin(1, sqrt(h)));
	return step > JUMP_HEIGHTS * fmax(agl, v->last_agl);
}

/* The frame's camera: its height above the ground, the levels it wants and its horizon. */
static void frame_camera(struct view *v, const struct view_camera *cam, struct frame *f)
{
	/* A jump leaves no velocity behind: else the look-ahead would ask for tiles along it, the
	 * prefetch ring only on its far side, and the want-set would change again frame after
	 * frame while the smoothed speed decays. */
	f->agl = fmax(cam->alt, 0.05);
	if (jumped(v, cam, f->agl, f->now_s))
		view_clipmap_motion_reset(v->cm);
	v->last_agl = f->agl;

	/* Camera: height above the terrain as far as the clipmap knows it. */
	v->last = *cam;
	v->last.width = v->d.width;
	v->last.height = v->d.height;
	double ground = surface_height(v, cam->lon, cam->lat);
	v->last.alt = ground * v->d.exaggeration + f->agl;
	f->s.ground = ground;
	f->s.agl = f->agl;
	f->s.alt = v->last.alt;

	view_level_range(&v->body, &v->last, f->agl, v->d.n_phi, v->max_level, &f->lmin, &f->lmax);
	f->dmax = view_detail_max(&v->body, &v->last, f->agl, v->T, f->lmax, v->max_level);
	f->s.lmin = f->lmin;
	f->s.lmax = f->lmax;
	f->s.dmax = f->dmax;
	f->cap = view_horizon_cap(&v->body, v->last.alt);
}

/* Algorithm 1, lines 2-9: the levels' targets and the look-ahead, the tiles that arrived, and
 * a new want-set where the focus changed. Returns 0 or -errno. */
static int frame_receive(struct view *v, const struct view_camera *cam, struct frame *f)
{
	bool changed = !v->sent_once;
	if (v->color_next >= 0) {
		changed |= view_clipmap_set_color(v->cm, v->color_next) == 1;
		v->color_next = -1;
	}
	set_targets(v, f->lmin, f->dmax, &changed);
	/* The look-ahead along the camera's motion (real time only: a frame without time —
	 * offline rendering — has no motion). */
	if (f->now_s > 0)
		changed |= view_clipmap_motion(v->cm, cam->lon, cam->lat, f->now_s);
	/* Real time: the tiles that arrived, for VIEW_RECEIVE_MS at most (the rest wait in the
	 * socket for the idle time between frames, or the next frame). */
	int rc = view_clipmap_receive(v->cm,
				      v->d.budget_ms > 0 ? clock_now_ms() + VIEW_RECEIVE_MS : 0);
	if (rc < 0)
		return rc;
	f->s.tiles_received = rc + v->idle_tiles;
	v->idle_tiles = 0;
	if (!changed)
		return 0;
	size_t n = view_clipmap_wants(v->cm, !v->d.no_prefetch, v->wants, MAX_WANTS);
	struct view_focus foc = { cam->lon, cam->lat, v->last.alt, { 0, 0, 0 } };
	rc = v->src->ops->want(v->src, v->wants, n, &foc);
	if (rc < 0)
		return rc;
	v->sent_once = true;
	f->s.wants_sent = n ? n : 1;
	return 0;
}

/* Binds the framebuffer and clears it to the background (kept in v->bg) with the depth test
 * set for the frame's depth range; binds the geometry. */
static void frame_clear(struct view *v, double agl)
{
	const struct gl *gl = v->gl;
	gl->BindFramebuffer(GL_FRAMEBUFFER, v->fbo);
	gl->Viewport(0, 0, v->d.width, v->d.height);
	float bg[3];
	if (v->d.background_set) {
		memcpy(bg, v->d.background, sizeof bg);
	} else {
		/* space, turning to the sky's colour inside the atmosphere (none without air); on
		 * Earth the blue fades out over 35 km */
		double sky = v->air.on ? exp(-agl / (4.375 * v->air.height)) : 0;
		bg[0] = (float)(0.01 + v->air.sky[0] * sky);
		bg[1] = (float)(0.01 + v->air.sky[1] * sky);
		bg[2] = (float)(0.03 + v->air.sky[2] * sky);
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
	gl->BindVertexArray(v->vao);
}

/* The plan: coarse → fine, each level that can be drawn (its texture's window covers its
 * ring). The first is the finest that reaches the horizon; the last is drawn as a disk,
 * the others as rings, each stretched over the rings of the levels missing below it (after
 * a jump, or when a level's tiles are late): every resident level is drawn, the budget
 * limits only the uploads of new quads (in usable()), and a still camera never loses a
 * level. Fills v->drawn and v->fade, f->first, f->last, f->nd and f->complete. */
static void frame_plan(struct view *v, struct frame *f)
{
	int first = -1, last = -1, nd = 0;
	for (int j = f->lmin; j >= 0 && first < 0; j--)
		if (usable(v, j, fmin(clipmap_ring_radius(j), f->cap), &f->up))
			first = j;
	bool detailed = true;
	for (int i = first; i >= 0 && i <= f->lmax; i++) {
		double r = fmin(clipmap_ring_radius(i), f->cap);
		if (i != first && !usable(v, i, r, &f->up)) {
			v->was_usable[i] = false;
			continue;
		}
		if (!v->was_usable[i]) {
			v->was_usable[i] = true;
			v->ready_since[i] = f->now_s;
		}
		v->fade[i] = 1;
		if (v->d.fade_s > 0 && i != first)
			v->fade[i] = fmin(1, (f->now_s - v->ready_since[i]) / v->d.fade_s);
		/* Its colour and normals: the finest level up to CLIPMAP_DETAIL finer that covers it
		 * (coarse first, so the uploads the budget allows go to the coarser rings). */
		int want = i + CLIPMAP_DETAIL < f->dmax ? i + CLIPMAP_DETAIL : f->dmax;
		v->detail[i] = i;
		for (int l = i + 1; l <= want; l++)
			if (usable(v, l, r, &f->up))
				v->detail[i] = l;
		detailed &= v->detail[i] >= want;
		v->drawn[nd++] = i;
		last = i;
	}
	f->first = first;
	f->last = last;
	f->nd = nd;
	f->complete = first == f->lmin && nd == f->lmax - f->lmin + 1 && detailed;
}

/* floor[l]: the lowest height held by level l and every finer one up to lmax (INFINITY
 * while any of them holds nothing yet). */
static void level_floors(struct view *v, int lmax)
{
	double fl = INFINITY;
	bool known = true;
	for (int l = v->nlevels - 1; l >= 0; l--) {
		double lo, hi;
		if (l > lmax)
			v->floor[l] = INFINITY;
		else if (known && drawn_range(v, l, &lo, &hi) == 0)
			v->floor[l] = fl = fmin(fl, lo);
		else
			v->floor[l] = fl = INFINITY, known = false;
	}
}

/* The lowest and highest ground levels i and c can draw over the cell θ̃ ∈ [th0, th1],
 * φ̃ ∈ [ph0, ph1] (their texels in a box around it: 3 × 3 samples of its (Δlon, Δlat), a
 * quarter of its size added), exaggerated, lifted to the sea. Returns false where unknown or
 * near a pole. */
static bool cell_range(struct view *v, int i, int c, double th0, double th1, double ph0,
		       double ph1, double *lo_out, double *hi_out)
{
	const struct view_camera *cam = &v->last;
	double g0[2] = { INFINITY, INFINITY }, g1[2] = { -INFINITY, -INFINITY };
	for (int a = 0; a < 3; a++)
		for (int k = 0; k < 3; k++) {
			double g[2];
			view_geo_delta(cam->lat, th0 + (th1 - th0) * a / 2, ph0 + (ph1 - ph0) * k / 2,
				       &g[0], &g[1]);
			for (int x = 0; x < 2; x++) {
				g0[x] = fmin(g0[x], g[x]);
				g1[x] = fmax(g1[x], g[x]);
			}
		}
	if (g1[0] - g0[0] > M_PI / 2)
		return false;
	for (int x = 0; x < 2; x++) {
		double pad = 0.25 * (g1[x] - g0[x]);
		g0[x] -= pad;
		g1[x] += pad;
	}
	double lo = INFINITY, hi = -INFINITY;
	for (int l = 0; l < 2; l++) {
		int lv = l ? c : i;
		double p[6], a, b;
		view_level_params(view_clipmap_held(v->cm, lv), cam->lon, cam->lat, p);
		if (view_clipmap_height_range_box(v->cm, lv, p[0] + g0[0] * p[2], p[0] + g1[0] * p[2],
						  fmax(p[1] - g1[1] * p[3], p[4]),
						  fmin(p[1] - g0[1] * p[3], p[5]), &a, &b) < 0)
			return false;
		lo = fmin(lo, a);
		hi = fmax(hi, b);
	}
	if (v->src->planet.look.sea) {
		lo = fmax(lo, v->sea_lo);
		hi = fmax(hi, v->sea_hi);
	}
	*lo_out = lo * v->d.exaggeration;
	*hi_out = hi * v->d.exaggeration;
	return true;
}

/* After level i (blended towards c) is drawn: raises the horizon of each subsector to the
 * greatest over its ring's cells (HSUB_TH across the ring) of the least elevation of the
 * cell's lowest ground (cell_range): every line of sight in the subsector's directions
 * crosses each cell (the ground is continuous from the nadir out), so meets ground at least
 * that high no farther than the ring's outer edge. Near a pole, nothing. */
static void horizon_add(struct view *v, int i)
{
	double r0 = clipmap_ring_radius(i + 1), r1 = fmin(clipmap_ring_radius(i), v->frame_cap);
	const struct view_camera *cam = &v->last;
	struct hcache *h = &v->hc[i];
	int ns = v->nsec * HSUB_PH;
	if (!v->cull || r0 >= r1 || fabs(cam->lat) + 2 * r1 / DEG >= 89)
		return;
	for (int s = 0; s < ns; s++) {
		if (h->hz[s] > -INFINITY && v->need[s / HSUB_PH])
			v->horizon[s] = fmax(v->horizon[s], h->hz[s]);
	}
}

/* The level's cache entry for this frame's camera and heights (emptied when they changed). */
static void hcache_check(struct view *v, int i, int c, int last, bool occluder)
{
	const struct view_camera *cam = &v->last;
	struct hcache *h = &v->hc[i];
	double key[9] = { cam->lon, cam->lat, cam->alt, cam->heading, cam->pitch, cam->fov_y,
			  v->frame_cap, last, occluder };
	uint64_t hv[2] = { view_clipmap_height_version(v->cm, i),
			   view_clipmap_height_version(v->cm, c) };
	if (h->valid && h->c == c && memcmp(h->key, key, sizeof key) == 0 &&
	    memcmp(h->hver, hv, sizeof hv) == 0)
		return;
	h->valid = true;
	h->c = c;
	memcpy(h->key, key, sizeof key);
	memcpy(h->hver, hv, sizeof hv);
	for (int p = 0; p < 3; p++)
		for (int s = 0; s < 32; s++)
			h->hi[p][s] = NAN;
	int ns = v->nsec * HSUB_PH;
	double r0 = clipmap_ring_radius(i + 1), r1 = fmin(clipmap_ring_radius(i), v->frame_cap);
	for (int s = 0; s < ns; s++) {
		h->hz[s] = -INFINITY;
		if (!occluder || !v->need[s / HSUB_PH] || r0 >= r1 ||
		    fabs(cam->lat) + 2 * r1 / DEG >= 89)
			continue;
		double ph0 = 2 * M_PI * sector_k(v, s / HSUB_PH) / v->d.n_phi;
		double ph1 = 2 * M_PI * sector_k(v, s / HSUB_PH + 1) / v->d.n_phi;
		double q0 = ph0 + (ph1 - ph0) * (s % HSUB_PH) / HSUB_PH;
		double q1 = ph0 + (ph1 - ph0) * (s % HSUB_PH + 1) / HSUB_PH;
		for (int b = 0; b < HSUB_TH; b++) {
			double th0 = r0 * pow(r1 / r0, (double)b / HSUB_TH);
			double th1 = r0 * pow(r1 / r0, (double)(b + 1) / HSUB_TH);
			double lo, hi;
			if (cell_range(v, i, c, th0, th1, q0, q1, &lo, &hi))
				h->hz[s] = fmax(h->hz[s], view_sector_elev_min(&v->body, cam, th0,
									       th1, q0, q1, lo));
		}
	}
}

/* The sectors whose horizon can matter this frame: those that can be seen and their
 * neighbours (occluded() reads a neighbour's next subsector). */
static void horizon_need(struct view *v)
{
	bool seen[32];
	for (int s = 0; s < v->nsec; s++) {
		double ph0 = 2 * M_PI * sector_k(v, s) / v->d.n_phi;
		double ph1 = 2 * M_PI * sector_k(v, s + 1) / v->d.n_phi;
		seen[s] = !v->cull || view_sector_visible(&v->body, &v->last, 0, v->frame_cap, ph0,
							  ph1, v->frame_cap);
	}
	for (int s = 0; s < v->nsec; s++)
		v->need[s] = seen[s] || seen[(s + 1) % v->nsec] ||
			     seen[(s + v->nsec - 1) % v->nsec];
}

/* Draws the plan's levels fine → coarse: the nearer ground first, so the depth test rejects
 * what it hides before that is shaded (llvmpipe tests depth before running the fragment
 * shader). Returns 0, or -EINVAL if a program failed (the geometry unbound). */
static int frame_draw(struct view *v, struct frame *f)
{
	v->frame_cap = f->cap;
	bool half = v->mesh_mode == 2 || (v->mesh_mode == 0 && f->agl > MESH_HALF_ABOVE * v->body.a);
	v->cur_mesh = &v->mesh[half && v->nmesh > 1 ? 1 : 0];
	for (int s = 0; s < v->nsec * HSUB_PH; s++)
		v->horizon[s] = -INFINITY;
	horizon_need(v);
	for (int k = f->nd - 1; k >= 0; k--) {
		int i = v->drawn[k];
		/* A disk's geometry: its ring and the two finer ones, then a fan to the
		 * nadir. A disk coarser than lmin (level 0 after a jump, while the new place's
		 * levels come in) takes the rings as far as a disk of lmin would: inside its
		 * own fan, a cone, the horizon would be misplaced. */
		int to = k + 1 < f->nd ? v->drawn[k + 1] - 1 : (i > f->lmin ? i : f->lmin) + 2;
		if (to > v->nlevels - 1)
			to = v->nlevels - 1;
		/* the nearest ground hides the most: the finest HORIZON_LEVELS levels drawn are
		 * the occluders (each costs its cells' texels on the CPU when the camera moves) */
		hcache_check(v, i, k > 0 ? v->drawn[k - 1] : i, to, k >= f->nd - HORIZON_LEVELS);
		int64_t tri = draw_level(v, i, k > 0 ? v->drawn[k - 1] : i, to, k + 1 == f->nd,
					 v->fade[i], f->cap, &f->s.triangles_culled);
		if (tri < 0) {
			v->gl->BindVertexArray(0);
			return (int)tri;
		}
		f->s.triangles += (uint64_t)tri;
		horizon_add(v, i);
	}
	return 0;
}

/* Ends the frame: the levels not drawn are no longer usable (their fade-in starts again when
 * they are), the frame is complete when every wanted level was drawn at its target quad, GL
 * has finished, and the figures are in f->s. Returns 0, or -EIO on a GL error. */
static int frame_end(struct view *v, struct frame *f)
{
	const struct gl *gl = v->gl;
	f->s.lfirst = f->first;
	f->s.llast = f->last;
	f->s.levels_drawn = f->nd;
	f->s.ldetail = f->nd ? v->detail[f->last] : -1;
	for (int l = 0; l < v->nlevels; l++)
		if (l < f->first || l > f->last)
			v->was_usable[l] = false;
	bool complete = f->complete;
	for (int l = f->lmin; l <= f->dmax && complete; l++) {
		const struct grid_quad *h = view_clipmap_held(v->cm, l);
		const struct grid_quad *t = view_clipmap_target_of(v->cm, l);
		complete = h && t && grid_quad_equal(h, t) && !view_clipmap_color_stale(v->cm, l);
	}
	int cl = view_clipmap_color_layer(v->cm);
	f->s.color_layer = cl >= 0 ? v->src->planet.layer[cl].name : "";
	f->s.complete = complete;
	gl->BindVertexArray(0);
	gl->Finish();
	struct view_clipmap_stats cs1;
	view_clipmap_get_stats(v->cm, &cs1);
	f->s.bytes_uploaded = cs1.bytes_uploaded - f->cs0.bytes_uploaded;
	f->s.levels_uploaded = f->up.done;
	f->s.cpu_ms = clock_now_ms() - f->t0;
	return gl->GetError() == GL_NO_ERROR ? 0 : -EIO;
}

/* Seed 003 Algorithm 1: camera, want-set and tiles, the plan, drawing, figures. */
int view_frame(struct view *v, const struct view_camera *cam, double now_s,
	       struct view_frame_stats *st)
{
	struct frame f = { .t0 = clock_now_ms(), .now_s = now_s,
			   .s = { .lfirst = -1, .llast = -1, .ldetail = -1 } };
	view_clipmap_get_stats(v->cm, &f.cs0);
	frame_camera(v, cam, &f);
	int rc = frame_receive(v, cam, &f);
	if (rc < 0)
		return rc;
	/* Lines 10-26: coarse → fine, ring while the next level can be drawn, else disk. */
	frame_clear(v, f.agl);
	v->frame_no++;
	frame_uniforms(v, f.agl, f.cap);
	frame_plan(v, &f);
	level_floors(v, f.lmax);
	rc = frame_draw(v, &f);
	if (rc < 0)
		return rc;
	rc = frame_end(v, &f);
	if (st)
		*st = f.s;
	return rc;
}

int view_idle(struct view *v, double seconds)
{
	double end = clock_now_ms() + seconds * 1e3;
	int got = 0;
	for (;;) {
		double left = end - clock_now_ms();
		if (left <= 0)
			break;
		int rc = v->src->ops->wait(v->src, (int)ceil(left));
		if (rc == 1)
			rc = view_clipmap_receive(v->cm, end);
		if (rc < 0)
			return rc;
		got += rc;
	}
	v->idle_tiles += got;
	return got;
}

int view_frame_complete(struct view *v, const struct view_camera *c, double timeout_s,
			struct view_frame_stats *st, int *frames)
{
	double t0 = clock_now_ms();
	struct view_frame_stats s = { 0 };
	int n = 0, rc = 0;
	for (;;) {
		rc = view_frame(v, c, 0, &s);
		n++;
		if (rc < 0)
			break;
		/* The frame used the ground height known before its uploads: settled when the
		 * uploads did not change it. */
		bool settled = surface_height(v, c->lon, c->lat) == s.ground;
		if (s.complete && settled)
			break;
		double left = timeout_s * 1e3 - (clock_now_ms() - t0);
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
		err_set(err, "framebuffer %dx%d: out of range", width, height);
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

int view_find_color_layer(const struct view *v, const char *name, char err[256])
{
	const struct view_planet *p = &v->src->planet;
	int i = view_clipmap_color_find(v->cm, name);
	if (i >= 0 && view_clipmap_color_layer(v->cm) >= 0)
		return i;
	char list[200] = "";
	size_t n = 0;
	for (int k = 0; k < p->nlayers && n < sizeof list; k++)
		if (p->layer[k].format == PIX_COLOR)
			n += (size_t)snprintf(list + n, sizeof list - n, "%s%s", n ? ", " : "",
					      p->layer[k].name);
	err_set(err, "planet %s has no colour layer \"%s\" (its colour layers: %s)", p->name, name,
		n ? list : "none");
	return -EINVAL;
}

int view_set_color_layer(struct view *v, const char *name, char err[256])
{
	int i = view_find_color_layer(v, name, err);
	if (i < 0)
		return i;
	v->color_next = i;
	return 0;
}

const char *view_color_layer(const struct view *v)
{
	int i = v->color_next >= 0 ? v->color_next : view_clipmap_color_layer(v->cm);
	return i >= 0 ? v->src->planet.layer[i].name : NULL;
}
