/* view_clipmap — see view_clipmap.h. Each level keeps at most SLOTS tiles per role: the
 * tiles its window touches (up to (n+1)², n = CLIPMAP_WINDOW_TILES), the ring around them and the
 * look-ahead. A CPU copy of the height slices answers ground-height queries (camera height
 * above the terrain) without reading the GPU back, and, when the normals are derived, is
 * what they are made from (derive_normals).
 */
#include "view_clipmap.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/geo.h"
#include "common/normalmap.h"
#include "common/xalloc.h"
#include "view_levels.h"

/* Per role: the window's tiles and their ring ((n+3)², a line of the ring n+3 long), the
 * look-ahead (≤ 2 × AHEAD_MAX lines) and the windows of the next lx's (NEXT_MAX of them, each
 * counted with its ring: (n+3)² a window).
 * AHEAD_MAX 2 until 5 December: a flight at 40× the seed over a warm store (46°N, 6000 m)
 * crosses ~110 tiles a second of its finest level, and 2 lines beyond the ring asked for them
 * ~27 ms before they were due, less than a tile's round trip: 89.5 and 90.6 % of its frames
 * complete with the CPU 72 % busy; with 6, 94.8 and 97.9 % (bench_keepup restarted, single
 * 8 s flights). Cold flights (4–8× the seed) gained a search step on four of nine rows and
 * lost none (one search each, the same machine). */
#define AHEAD_MAX 6
#define LINE (CLIPMAP_WINDOW_TILES + 3)
/* The windows of the lx changes ahead asked for, nearest first: the first within NEXT_LEAD_S
 * (with its ring on the side the camera moves to), up to NEXT_MAX − 1 more within
 * NEXT2_LEAD_S (the window alone). Over a pole a level changes lx every few tenths of a
 * degree, and a switch that followed another within a few frames had its window asked for
 * only at the first. Pole trials (2 s, 3.5× the seed, alternated with the first window
 * alone, 6 December): 800 km 100 / 100 % of frames complete against 95.8 / 95.0 %, 80 km
 * 87.5 / 84.2 % against 72.5 / 75.8 %, 20 km and 6000 m the same; with the later windows
 * over the whole 1.2 s, or each with its ring, 20 km made 12–14 % more tiles and fell to
 * 85–89 %. */
#define NEXT_MAX 3
#define NEXT2_LEAD_S 0.6
#define NEXT_TILES (NEXT_MAX * LINE * LINE)
#define SLOTS (LINE * LINE + LINE * 2 * AHEAD_MAX + NEXT_TILES)
#define AHEAD_LEAD_S 0.15   /* look ahead as far as the camera moves in this time */
/* Ask for the window of the next lx this long before it is due. 0.4 s until 4 December: at
 * 70°N from 800 km a switched window of cold tiles took longer than that to make, and 8 s
 * flights at the seed's velocity had 91 % of their frames complete (100 % with 1.2 s); over
 * a pole, where levels switch often, 1.2 s measured the same as 0.4 and 2.5 s worse
 * (bench_keepup, routes 70n and pole). */
#define NEXT_LEAD_S 1.2
/* The lead is walked in this many steps for the lx changes (each then bisected): at 800 km and
 * 2.5× the seed over a pole a step is ~0.3°, under the narrowest lx band of a level there. */
#define NEXT_STEPS 48
#define AHEAD_CAP 160	    /* look-ahead tiles per want-set, all levels and roles together */

struct slot {
	bool used;
	struct view_tile t;
};

struct level {
	bool has_target, has_held;
	struct grid_quad target, held;
	int ahead[2]; /* look-ahead lines beyond the ring: x (signed: + east), y (+ south) */
	int side[2];  /* per axis (x, y): the side (−1 west/north, +1 east/south) whose ring
		       * line is prefetched while the camera moves; 0: both */
	int nnext; /* the camera moves to where this level uses other lx's: */
	struct grid_quad next[NEXT_MAX]; /* its windows there, nearest first, asked for
					  * (look-ahead) before they are due */
	struct slot slots[VIEW_NROLES][SLOTS];
	float *hmirror; /* S × S heights, toroidal like the texture; NULL until first upload */
	uint8_t *amirror; /* S × S colour alpha (with view_clipmap_keep_alpha), like hmirror */
	bool hdirty;	/* hmirror changed since hlo/hhi were computed */
	float hlo, hhi; /* the heights' range over the whole slice */
	uint64_t hver;	/* counts hmirror's changes (from 1) */
	uint32_t cgen;	/* the colour generation its colour slice holds (view_clipmap.cgen) */
	struct near_range {
		double lon, lat, r; /* the disk */
		uint64_t hver;	    /* hmirror's version then (0: unset) */
		float lo, hi;
	} near[2]; /* the last two disks asked of view_clipmap_height_range_near */
	int near_next; /* the entry the next one replaces */
	/* with derive: each row's stencil figures, by level row v mod S (they depend on the
	 * row's latitude and the level's lx only; computing them is most of a thin strip's
	 * cost) */
	struct nrow_par {
		int64_t v; /* −1: unset */
		int lx;
		double dy, r, len;
		uint32_t k;
	} *nrp;
};

struct view_clipmap {
	const struct gl *gl;
	struct view_source *src;
	uint32_t T, S; /* tile size, window (texture) size */
	int nlevels;
	int layer[VIEW_NROLES]; /* source layer index per role, -1 absent */
	uint32_t cgen;		/* counts colour layer switches: a held level whose cgen differs
				 * draws the previous layer's colour until it is refilled */
	unsigned tex[VIEW_NROLES];
	bool derive;		 /* normals made from the heights (no normal layer asked for) */
	struct geo_body *body;	 /* with derive: the ellipsoid, for the metric spacing */
	uint8_t *nbuf;		 /* with derive: a region's normals, (T + 2)² RG8 */
	uint32_t *ncol;		 /* with derive: 2 column tables of (T + 2) + 2·T entries */
	float *nrow;		 /* with derive: a row's 4 stencil heights, 4 × (T + 2) */
	unsigned char *zeros; /* a T×T tile of zeros for tiles that failed */
	bool keep_alpha;      /* mirror the colour's alpha (view_clipmap_keep_alpha) */
	bool has_motion;       /* the camera's ground motion, smoothed: */
	double m_lon, m_lat, m_t, v_lon, v_lat; /* last position (deg), time (s), deg/s */
	struct level *lv;
	struct view_clipmap_stats st;
};

static const struct {
	const char *name;
	enum pix_type type;
	GLenum ifmt, fmt, gltype;
} roles[VIEW_NROLES] = {
	[VIEW_HEIGHT] = { "height", PIX_HEIGHT, GL_R32F, GL_RED, GL_FLOAT },
	[VIEW_NORMAL] = { "normal", PIX_NORMAL, GL_RG8, GL_RG, GL_UNSIGNED_BYTE },
	[VIEW_COLOR] = { "color", PIX_COLOR, GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE },
};

static bool same_tile(const struct tile_key *a, const struct tile_key *b)
{
	return a->x == b->x && a->y == b->y && a->lx == b->lx && a->ly == b->ly;
}

/* The layer of p that role r draws: the one named name (NULL: the role's own name, as
 * "height"), else (name NULL) the first of the role's format; -1 without one. */
static int pick_layer(const struct view_planet *p, enum view_role r, const char *name)
{
	const char *want = name ? name : roles[r].name;
	for (int i = 0; i < p->nlayers; i++)
		if (p->layer[i].format == roles[r].type && !strcmp(p->layer[i].name, want))
			return i;
	for (int i = 0; !name && i < p->nlayers; i++)
		if (p->layer[i].format == roles[r].type)
			return i;
	return -1;
}

bool view_clipmap_can_derive(const struct view_planet *p)
{
	int h = pick_layer(p, VIEW_HEIGHT, NULL), n = pick_layer(p, VIEW_NORMAL, NULL);
	return h >= 0 && (n < 0 || p->layer[n].normal_of == h + 1);
}

int view_clipmap_create(const struct gl *gl, struct view_source *src, int nlevels,
			struct view_clipmap **out, char err[256])
{
	return view_clipmap_create_layer(gl, src, nlevels, NULL, true, out, err);
}

int view_clipmap_create_layer(const struct gl *gl, struct view_source *src, int nlevels,
			      const char *color_layer, bool normals, struct view_clipmap **out,
			      char err[256])
{
	const struct view_planet *p = &src->planet;
	*out = NULL;
	if (nlevels < 1 || nlevels > VIEW_MAX_LEVELS || p->tile_size < 16 || p->tile_size > 4096) {
		err_set(err, "bad clipmap shape: %d levels of %u", nlevels, p->tile_size);
		return -EINVAL;
	}
	int layer[VIEW_NROLES];
	for (int r = 0; r < VIEW_NROLES; r++) {
		layer[r] = pick_layer(p, (enum view_role)r, r == VIEW_COLOR ? color_layer : NULL);
		if (r == VIEW_COLOR && color_layer && layer[r] < 0) {
			err_set(err, "planet %s has no colour layer \"%s\"", p->name, color_layer);
			return -EINVAL;
		}
	}
	if (!normals)
		layer[VIEW_NORMAL] = -1;
	if (layer[VIEW_HEIGHT] < 0) {
		err_set(err, "planet %s publishes no height layer", p->name);
		return -EINVAL;
	}
	struct geo_body *body = NULL;
	if (!normals && geo_body_create(p->a, p->f, &body, err) < 0)
		return -EINVAL;
	struct view_clipmap *cm = xcalloc(1, sizeof *cm);
	cm->gl = gl;
	cm->src = src;
	cm->T = p->tile_size;
	cm->S = CLIPMAP_WINDOW_TILES * cm->T;
	cm->nlevels = nlevels;
	memcpy(cm->layer, layer, sizeof layer);
	cm->derive = !normals;
	cm->body = body;
	if (cm->derive) {
		cm->nbuf = xmalloc((size_t)(cm->T + 2) * (cm->T + 2) * 2);
		cm->ncol = xmalloc(2 * ((size_t)cm->T + 2 + 2 * (size_t)cm->T) * sizeof *cm->ncol);
		cm->nrow = xmalloc(4 * ((size_t)cm->T + 2) * sizeof *cm->nrow);
	}
	cm->zeros = xcalloc((size_t)cm->T * cm->T, 4);
	cm->lv = xcalloc((size_t)nlevels, sizeof *cm->lv);
	while (gl->GetError() != GL_NO_ERROR)
		;
	for (int r = 0; r < VIEW_NROLES; r++) {
		if (layer[r] < 0 && !(r == VIEW_NORMAL && cm->derive))
			continue;
		gl->GenTextures(1, &cm->tex[r]);
		gl->BindTexture(GL_TEXTURE_2D_ARRAY, cm->tex[r]);
		gl->TexImage3D(GL_TEXTURE_2D_ARRAY, 0, (GLint)roles[r].ifmt, (GLsizei)cm->S,
			       (GLsizei)cm->S, nlevels, 0, roles[r].fmt, roles[r].gltype, NULL);
		gl->TexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
		gl->TexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
		gl->TexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_REPEAT);
		gl->TexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_REPEAT);
		gl->TexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAX_LEVEL, 0);
	}
	GLenum e = gl->GetError();
	if (e != GL_NO_ERROR) {
		err_set(err, "clipmap textures (%d × %u²): GL error 0x%x", nlevels, cm->S, e);
		view_clipmap_destroy(cm);
		return -ENOMEM;
	}
	*out = cm;
	return 0;
}

static void drop(struct view_clipmap *cm, struct slot *s)
{
	if (!s->used)
		return;
	cm->src->ops->release(cm->src, &s->t);
	s->used = false;
	cm->st.tiles_held--;
}

void view_clipmap_destroy(struct view_clipmap *cm)
{
	if (!cm)
		return;
	for (int l = 0; l < cm->nlevels; l++) {
		for (int r = 0; r < VIEW_NROLES; r++)
			for (int i = 0; i < SLOTS; i++)
				drop(cm, &cm->lv[l].slots[r][i]);
		free(cm->lv[l].hmirror);
		free(cm->lv[l].nrp);
		free(cm->lv[l].amirror);
	}
	for (int r = 0; r < VIEW_NROLES; r++)
		if (cm->tex[r])
			cm->gl->DeleteTextures(1, &cm->tex[r]);
	free(cm->lv);
	free(cm->zeros);
	free(cm->nbuf);
	free(cm->ncol);
	free(cm->nrow);
	geo_body_destroy(cm->body);
	free(cm);
}

/* Whether a ring-line offset d ∈ [−1, n] from the window's first tile (n tiles along that
 * axis) is on the side an axis prefetches (side −1: offsets −1..n−1, +1: 0..n, 0: all). */
static bool on_side(int side, int64_t d, int n)
{
	return side == 0 || (side < 0 ? d <= n - 1 : d >= 0);
}

/* The look-ahead tiles of a level: lines (columns for x, rows for y) at distances 2 ..
 * 1 + |ahead| from the window on the side the camera moves to, each as long as the ring. */
static int ahead_tiles(const struct level *L, struct tile_key out[LINE * 2 * AHEAD_MAX])
{
	const struct grid_quad *q = &L->target;
	int n = 0;
	int64_t ny = grid_tiles_y(q->ly);
	for (int s = 2; s <= 1 + abs(L->ahead[0]); s++) {
		int64_t x = L->ahead[0] > 0 ? (int64_t)q->tx0 + q->ntx - 1 + s : (int64_t)q->tx0 - s;
		for (int64_t dy = -1; dy <= q->nty; dy++) {
			int64_t y = (int64_t)q->ty0 + dy;
			if (y >= 0 && y < ny && on_side(L->side[1], dy, q->nty))
				out[n++] = (struct tile_key){ 0, grid_wrap_x(q->lx, x), (uint32_t)y, q->lx,
							      q->ly };
		}
	}
	for (int s = 2; s <= 1 + abs(L->ahead[1]); s++) {
		int64_t y = L->ahead[1] > 0 ? (int64_t)q->ty0 + q->nty - 1 + s : (int64_t)q->ty0 - s;
		if (y < 0 || y >= ny)
			continue;
		for (int64_t dx = -1; dx <= q->ntx; dx++)
			if (on_side(L->side[0], dx, q->ntx))
				out[n++] = (struct tile_key){ 0, grid_wrap_x(q->lx, (int64_t)q->tx0 + dx),
							      (uint32_t)y, q->lx, q->ly };
	}
	return n;
}

/* Whether level L wants tile k now: in or next to the target quad, or ahead of it. */
static bool wanted(const struct level *L, const struct tile_key *k)
{
	if (!L->has_target)
		return false;
	if (grid_quad_distance(&L->target, k) <= 1)
		return true;
	for (int i = 0; i < L->nnext; i++)
		if (grid_quad_distance(&L->next[i], k) <= 1)
			return true;
	struct tile_key a[LINE * 2 * AHEAD_MAX];
	int n = ahead_tiles(L, a);
	for (int i = 0; i < n; i++)
		if (same_tile(&a[i], k))
			return true;
	return false;
}

static void drop_unwanted(struct view_clipmap *cm, struct level *L)
{
	for (int r = 0; r < VIEW_NROLES; r++)
		for (int i = 0; i < SLOTS; i++)
			if (L->slots[r][i].used && !wanted(L, &L->slots[r][i].t.key))
				drop(cm, &L->slots[r][i]);
}

/* Where the camera will be t seconds on: along the great circle of its smoothed ground
 * motion (its east and north components; across a pole too). */
static void path_point(const struct view_clipmap *cm, double t, double *lat, double *lon)
{
	const double rad = M_PI / 180.0;
	/* degrees of arc per second; within 10° of a pole the smoothed longitude rate is still
	 * full of a turn about the pole or a crossing (a camera circling it sweeps 360°/s), so
	 * only the motion north or south is followed there */
	double ve = fabs(cm->m_lat) < 80 ? cm->v_lon * cos(cm->m_lat * rad) : 0, vn = cm->v_lat;
	view_sphere_direct(cm->m_lat, cm->m_lon, atan2(ve, vn), hypot(ve, vn) * t * rad, lat, lon);
	*lon = remainder(*lon, 360.0);
}

bool view_clipmap_motion(struct view_clipmap *cm, double lon, double lat, double t)
{
	if (cm->has_motion && t > cm->m_t) {
		double dt = t - cm->m_t, a = fmin(1.0, dt / 0.1); /* ~0.1 s smoothing */
		double dlon = remainder(lon - cm->m_lon, 360.0), dlat = lat - cm->m_lat;
		if (fabs(dlon) > 90) {
			/* across a pole: the longitude jumped, and north turned to south. A rate
			 * from this step would be ~180° a frame, which the smoothing took most
			 * of a second to forget (the look-ahead went sideways off the path). */
			cm->v_lat = -cm->v_lat;
		} else {
			cm->v_lon += a * (dlon / dt - cm->v_lon);
			cm->v_lat += a * (dlat / dt - cm->v_lat);
		}
	} else if (!cm->has_motion) {
		cm->v_lon = cm->v_lat = 0;
	}
	cm->has_motion = true;
	cm->m_lon = lon;
	cm->m_lat = lat;
	cm->m_t = t;
	bool changed = false;
	double walk[NEXT_STEPS]; /* the path's latitudes over the lead, for the lx changes ahead */
	for (int st = 1; st <= NEXT_STEPS && cm->v_lat != 0; st++) {
		double lon_w;
		path_point(cm, NEXT_LEAD_S * st / NEXT_STEPS, &walk[st - 1], &lon_w);
	}
	for (int l = 0; l < cm->nlevels; l++) {
		struct level *L = &cm->lv[l];
		int a[2] = { 0, 0 };
		if (L->has_target) {
			/* tiles crossed in the lead time, per axis */
			double nx = cm->v_lon * AHEAD_LEAD_S / (360.0 / ldexp(1.0, L->target.lx));
			double ny = -cm->v_lat * AHEAD_LEAD_S / (180.0 / ldexp(1.0, L->target.ly));
			for (int i = 0; i < 2; i++) {
				double v = i ? ny : nx;
				int k = (int)fmin(AHEAD_MAX, floor(fabs(v) + 0.5));
				a[i] = v < 0 ? -k : k;
			}
			/* Rows ahead only as far as this lx stays the one the level uses when
			 * its window first touches them (clipmap_level_lx, as prefetch decides
			 * it): near a pole it changes within a few rows, and a row of the lx
			 * left behind is never shown. The window reaches 2 rows each side of
			 * its focus. */
			const struct grid_quad *q = &L->target;
			double row = 180.0 / ldexp(1.0, q->ly);
			for (int s = 2; s <= 1 + abs(a[1]); s++) {
				int64_t y = a[1] > 0 ? (int64_t)q->ty0 + q->nty - 1 + s
						     : (int64_t)q->ty0 - s;
				double fy = a[1] > 0 ? (double)y - CLIPMAP_WINDOW_TILES / 2
						     : (double)y + 1 + CLIPMAP_WINDOW_TILES / 2;
				double la = fmax(-90.0, fmin(90.0, 90.0 - fy * row));
				if (clipmap_level_lx(l, la, q->lx) != q->lx) {
					a[1] = a[1] > 0 ? s - 2 : 2 - s;
					break;
				}
			}
		}
		/* The ring is prefetched on the side the camera moves to: along an axis it moves on
		 * (over 1/50 tile a second), the line behind is not asked for — new tiles there
		 * would only be needed if it turned back, and the line it just left is still held.
		 * Along an axis it does not move on while it moves on the other, the nearer side
		 * (where the window switches tiles first). At rest, the whole ring. The swath along
		 * a path is then three tiles wide, not four: a quarter less synthesis at speed. */
		int sd[2] = { 0, 0 };
		if (L->has_target) {
			double vt[2] = { cm->v_lon / (360.0 / ldexp(1.0, L->target.lx)),
					 -cm->v_lat / (180.0 / ldexp(1.0, L->target.ly)) };
			int64_t off[2] = { L->target.u0 % L->target.T, L->target.v0 % L->target.T };
			bool moving[2] = { fabs(vt[0]) > 0.02, fabs(vt[1]) > 0.02 };
			for (int i = 0; i < 2; i++)
				if (moving[i])
					sd[i] = vt[i] > 0 ? 1 : -1;
				else if (moving[1 - i])
					sd[i] = off[i] < (int64_t)L->target.T / 2 ? -1 : 1;
		}
		if (sd[0] != L->side[0] || sd[1] != L->side[1]) {
			/* what is asked for changes, not what is kept (the whole ring stays wanted) */
			L->side[0] = sd[0];
			L->side[1] = sd[1];
			changed = true;
		}
		/* Where the camera will be NEXT_LEAD_S on, this level may use another lx (the
		 * levels turn coarser in x towards a pole, finer away from it: clipmap_level_lx).
		 * Its window there is a new set of tiles, none of them in the ring or the rows
		 * ahead (those stop where the lx changes): asked for now, they are here when the
		 * level switches. Without it each switch waited a round trip with the level
		 * stale (a pole flight's short frames were all such switches). With the window,
		 * its ring on the side the camera moves to (wants): the row the window moves
		 * into next, which over a pole comes a few frames after the switch — asked for
		 * at the switch, it came late (6 December: 2 s pole trials at 2.5× the seed,
		 * 800 km 97.5 % of frames complete against 95.8 % without, 20 km 99–100 %
		 * against 92 %). Then the changes after it (NEXT_MAX). */
		int nn = 0;
		struct grid_quad next[NEXT_MAX];
		if (L->has_target && cm->v_lat != 0) { /* lx follows latitude alone */
			int cur = clipmap_level_lx(l, cm->m_lat, L->target.lx);
			/* the points of the path where the lx changes: the lead walked in
			 * NEXT_STEPS steps (over a pole the path's lx goes down, then up again),
			 * each change then bisected within its step; the lx after a change is
			 * the one the next is looked for from, as the viewer will hold it */
			double lat_f, lon_f, f0 = 0;
			for (int st = 1; st <= NEXT_STEPS && nn < NEXT_MAX; st++) {
				double f1 = (double)st / NEXT_STEPS;
				if (clipmap_level_lx(l, walk[st - 1], cur) == cur) {
					f0 = f1;
					continue;
				}
				for (int i = 0; i < 20; i++) {
					double f = (f0 + f1) / 2;
					path_point(cm, NEXT_LEAD_S * f, &lat_f, &lon_f);
					if (clipmap_level_lx(l, lat_f, cur) != cur)
						f1 = f;
					else
						f0 = f;
				}
				if (nn > 0 && NEXT_LEAD_S * f1 > NEXT2_LEAD_S)
					break;
				path_point(cm, NEXT_LEAD_S * f1, &lat_f, &lon_f);
				int lx = clipmap_level_lx(l, lat_f, cur);
				if (!grid_level_valid(lx, l))
					break;
				grid_window(lx, l, L->target.T, cm->S, lon_f, lat_f, &next[nn++]);
				cur = lx;
				f0 = f1;
				st--; /* the rest of this step: another change may follow in it */
			}
		}
		bool next_changed = nn != L->nnext;
		for (int i = 0; i < nn && !next_changed; i++)
			next_changed = !grid_quad_equal(&next[i], &L->next[i]);
		if (a[0] != L->ahead[0] || a[1] != L->ahead[1] || next_changed) {
			L->ahead[0] = a[0];
			L->ahead[1] = a[1];
			L->nnext = nn;
			memcpy(L->next, next, (size_t)nn * sizeof next[0]);
			changed = true;
			drop_unwanted(cm, L);
		}
	}
	return changed;
}

void view_clipmap_motion_reset(struct view_clipmap *cm)
{
	cm->has_motion = false;
	cm->v_lon = cm->v_lat = 0;
}

bool view_clipmap_target(struct view_clipmap *cm, int level, const struct grid_quad *q)
{
	struct level *L = &cm->lv[level];
	if (!q) {
		bool changed = L->has_target;
		L->has_target = false;
		L->ahead[0] = L->ahead[1] = 0;
		L->side[0] = L->side[1] = 0;
		L->nnext = 0;
		for (int r = 0; r < VIEW_NROLES; r++)
			for (int i = 0; i < SLOTS; i++)
				drop(cm, &L->slots[r][i]);
		return changed;
	}
	if (L->has_target && grid_quad_equal(&L->target, q))
		return false;
	L->target = *q;
	L->has_target = true;
	drop_unwanted(cm, L);
	return true;
}

static struct slot *find(struct level *L, int role, const struct tile_key *k)
{
	for (int i = 0; i < SLOTS; i++)
		if (L->slots[role][i].used && same_tile(&L->slots[role][i].t.key, k))
			return &L->slots[role][i];
	return NULL;
}

/* The ring around window q (prefetch: tiles at distance 1), less the lines behind the
 * camera's motion (side: level.side), deduplicated. Returns the count. */
static int ring_tiles(const struct grid_quad *q, const int side[2],
		      struct tile_key out[LINE * LINE])
{
	int n = 0;
	int64_t ny = grid_tiles_y(q->ly);
	for (int64_t dy = -1; dy <= q->nty; dy++) {
		int64_t y = (int64_t)q->ty0 + dy;
		if (y < 0 || y >= ny || !on_side(side[1], dy, q->nty))
			continue;
		for (int64_t dx = -1; dx <= q->ntx; dx++) {
			if (!on_side(side[0], dx, q->ntx))
				continue;
			struct tile_key k = { 0, grid_wrap_x(q->lx, (int64_t)q->tx0 + dx), (uint32_t)y,
					      q->lx, q->ly };
			if (grid_quad_distance(q, &k) != 1)
				continue;
			bool dup = false;
			for (int i = 0; i < n && !dup; i++)
				dup = same_tile(&out[i], &k);
			if (!dup)
				out[n++] = k;
		}
	}
	return n;
}

/* Sorts a window's tiles (grid_quad_tiles' order) from its middle out: by the Chebyshev
 * distance of each tile's centre from the window's centre (the cores view_clipmap_update
 * draws first are squares about it), then the Euclidean. Stable; n ≤ GRID_WINDOW_MAX_KEYS. */
static void middle_out(const struct grid_quad *q, struct tile_key *k, int n)
{
	double cu = (double)q->u0 + q->w / 2.0, cv = (double)q->v0 + q->h / 2.0, T = q->T;
	double key[GRID_WINDOW_MAX_KEYS][2];
	for (int i = 0; i < n; i++) {
		double dx = ((double)q->tx0 + i % q->ntx + 0.5) * T - cu;
		double dy = ((double)q->ty0 + i / q->ntx + 0.5) * T - cv;
		key[i][0] = fmax(fabs(dx), fabs(dy));
		key[i][1] = dx * dx + dy * dy;
	}
	for (int i = 1; i < n; i++) {
		struct tile_key kt = k[i];
		double a = key[i][0], b = key[i][1];
		int j = i;
		for (; j > 0 && (key[j - 1][0] > a || (key[j - 1][0] == a && key[j - 1][1] > b));
		     j--) {
			k[j] = k[j - 1];
			key[j][0] = key[j - 1][0];
			key[j][1] = key[j - 1][1];
		}
		k[j] = kt;
		key[j][0] = a;
		key[j][1] = b;
	}
}

size_t view_clipmap_wants(const struct view_clipmap *cm, bool prefetch, struct view_want *out,
			  size_t cap)
{
	size_t n = 0, ahead = 0;
	static const enum view_class cls[3] = { VIEW_CLASS_VISIBLE, VIEW_CLASS_PREFETCH,
						VIEW_CLASS_AHEAD };
	for (int pass = 0; pass < (prefetch ? 3 : 1); pass++) {
		for (int l = 0; l < cm->nlevels; l++) {
			struct level *L = &cm->lv[l];
			if (!L->has_target)
				continue;
			struct tile_key k[SLOTS];
			/* look-ahead: the next lx's window and its ring on the side the camera
			 * moves to first, then the windows of the changes after it (none counted
			 * against AHEAD_CAP: at most (n+3)² + 2 (n+1)² a level, and only near
			 * where a level's lx changes), then the rows ahead */
			int nnext = 0;
			for (int i = 0; pass == 2 && i < L->nnext; i++) {
				/* the first window with its ring, the others alone; a tile an
				 * earlier one has (over a pole an lx comes back) once */
				struct tile_key w[LINE * LINE];
				int m = grid_quad_tiles(&L->next[i], 0, w);
				if (i == 0)
					m += ring_tiles(&L->next[i], L->side, w + m);
				for (int t = 0; t < m; t++) {
					bool dup = false;
					for (int e = 0; e < nnext && !dup; e++)
						dup = same_tile(&k[e], &w[t]);
					if (!dup)
						k[nnext++] = w[t];
				}
			}
			int nk = pass == 0   ? grid_quad_tiles(&L->target, 0, k)
				 : pass == 1 ? ring_tiles(&L->target, L->side, k)
					     : nnext + ahead_tiles(L, k + nnext);
			/* the window from its middle out, each tile's layers together: the cores
			 * a level is drawn from first arrive first (screen importance: the middle
			 * is the ground under and around the camera, the nearest on screen) */
			if (pass == 0)
				middle_out(&L->target, k, nk);
			for (int i = 0; i < nk; i++) {
				bool capped = pass == 2 && i >= nnext;
				for (int r = 0; r < VIEW_NROLES; r++) {
					if (cm->layer[r] < 0 || find(L, r, &k[i]) || n >= cap ||
					    (capped && ahead >= AHEAD_CAP))
						continue;
					ahead += capped;
					out[n++] = (struct view_want){ (uint8_t)cm->layer[r], cls[pass],
								       k[i] };
				}
			}
		}
	}
	return n;
}

int view_clipmap_receive(struct view_clipmap *cm, double until_ms)
{
	int got = 0;
	struct view_tile t;
	int rc = 0;
	while ((until_ms <= 0 || got < VIEW_RECEIVE_MIN || clock_now_ms() < until_ms) &&
	       (rc = cm->src->ops->poll(cm->src, &t)) == 1) {
		got++;
		cm->st.tiles_received++;
		int role = -1;
		for (int r = 0; r < VIEW_NROLES; r++)
			if (cm->layer[r] == t.layer)
				role = r;
		int l = t.key.ly;
		struct level *L = l < cm->nlevels ? &cm->lv[l] : NULL;
		bool keep = role >= 0 && L && wanted(L, &t.key) && !find(L, role, &t.key) &&
			    t.size == cm->T && t.format == roles[role].type;
		struct slot *s = NULL;
		for (int i = 0; keep && i < SLOTS && !s; i++)
			if (!L->slots[role][i].used)
				s = &L->slots[role][i];
		for (int i = 0; keep && i < SLOTS && !s; i++) /* a tile the level no longer wants */
			if (!wanted(L, &L->slots[role][i].t.key)) {
				drop(cm, &L->slots[role][i]);
				s = &L->slots[role][i];
			}
		if (!s) {
			cm->st.tiles_dropped++;
			cm->src->ops->release(cm->src, &t);
			continue;
		}
		if (t.err < 0 || !t.texels)
			cm->st.tiles_failed++;
		s->used = true;
		s->t = t;
		cm->st.tiles_held++;
	}
	return rc < 0 ? rc : got;
}

/* The window's level is narrower than the texture (the coarsest levels): its columns repeat
 * every W texels across it, so GL_REPEAT at S still wraps longitude. */
static uint32_t level_period(const struct view_clipmap *cm, const struct grid_quad *q)
{
	uint64_t W = (uint64_t)grid_tiles_x(q->lx) * cm->T;
	return W < cm->S ? (uint32_t)W : cm->S;
}

static void mirror_region(struct view_clipmap *cm, struct level *L, const struct grid_region *r,
			  const unsigned char *tile, uint32_t period)
{
	uint32_t T = cm->T, S = cm->S;
	if (!L->hmirror)
		L->hmirror = xcalloc((size_t)S * S, sizeof(float));
	for (uint32_t x = r->x; x < S; x += period)
		for (uint32_t j = 0; j < r->h; j++)
			memcpy(L->hmirror + (size_t)(r->y + j) * S + x,
			       tile + ((size_t)(r->sy + j) * T + r->sx) * 4, (size_t)r->w * 4);
	L->hdirty = true;
	L->hver++;
}

/* The colour region's alpha into the level's alpha mirror. */
static void mirror_alpha(struct view_clipmap *cm, struct level *L, const struct grid_region *r,
			 const unsigned char *tile, uint32_t period)
{
	uint32_t T = cm->T, S = cm->S;
	if (!L->amirror)
		L->amirror = xcalloc((size_t)S * S, 1);
	for (uint32_t x = r->x; x < S; x += period)
		for (uint32_t j = 0; j < r->h; j++) {
			uint8_t *d = L->amirror + (size_t)(r->y + j) * S + x;
			const unsigned char *s = tile + ((size_t)(r->sy + j) * T + r->sx) * 4 + 3;
			for (uint32_t i = 0; i < r->w; i++)
				d[i] = s[4 * i];
		}
}

void view_clipmap_keep_alpha(struct view_clipmap *cm, bool on)
{
	cm->keep_alpha = on;
}

/* ---- normals made from the heights (derive) ---- */

/* Level texel u wrapped into [0, W). */
static int64_t wrap_u(int64_t u, int64_t W)
{
	u %= W;
	return u < 0 ? u + W : u;
}

/* Copies w × h RG8 normals (rows of w) for level texels from (u, v) into the normal slice:
 * split where the texture wraps, repeated across it where the level is narrower than S. */
static void upload_normals(struct view_clipmap *cm, int level, int64_t W, int64_t u, int64_t v,
			   uint32_t w, uint32_t h, const uint8_t *px)
{
	const struct gl *gl = cm->gl;
	uint32_t S = cm->S, period = W < S ? (uint32_t)W : S;
	gl->PixelStorei(GL_UNPACK_ROW_LENGTH, (GLint)w);
	for (uint32_t j = 0; j < h;) {
		uint32_t y = (uint32_t)((v + j) % S), nh = h - j < S - y ? h - j : S - y;
		for (uint32_t i = 0; i < w;) {
			int64_t uu = wrap_u(u + i, W);
			uint32_t x = (uint32_t)(uu % S);
			uint32_t nw = w - i;
			if (nw > period - x % period)
				nw = period - x % period;
			if ((int64_t)nw > W - uu)
				nw = (uint32_t)(W - uu);
			for (uint32_t xr = x % period; xr < S; xr += period) {
				gl->TexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, (GLint)xr, (GLint)y, level,
						  (GLsizei)nw, (GLsizei)nh, 1, GL_RG, GL_UNSIGNED_BYTE,
						  px + ((size_t)j * w + i) * 2);
				cm->st.bytes_uploaded += (uint64_t)nw * nh * 2;
				cm->st.regions_uploaded++;
			}
			i += nw;
		}
		j += nh;
	}
	gl->PixelStorei(GL_UNPACK_ROW_LENGTH, (GLint)cm->T);
}

/* A texel whose east stencil the window cuts (west: texels west of it in the window; c: its
 * index in col, the row's mirror columns): its normal again, with the stencil's ends and
 * length cut to the window. */
static void derive_cut(const struct grid_quad *q, int64_t west, int64_t k, double r, double dlam,
		       float fy, const float *row, const uint32_t *col, uint32_t c, float up,
		       float dn, uint8_t *out)
{
	int64_t east = (int64_t)q->w - 1 - west;
	int64_t kw = west < k ? west : k, ke = east < k ? east : k;
	float f = kw + ke == 0
			  ? 0.0f
			  : (float)(1.0 / (r * (sin((double)kw * dlam) + sin((double)ke * dlam))));
	normalmap_texel(row[col[c - kw]], row[col[c + ke]], up, dn, f, fy, out);
}

/* The normals of level texels [u0, u0 + w) × [v0, v0 + h) (inside the held window q) from the
 * height mirror, with the `normal` node's arithmetic (common/normalmap.h): central
 * differences, metric spacing on the ellipsoid, the wider east stencil near a pole, and
 * across a pole the texel half a turn round. Where a stencil leaves the window (its outer
 * texels) it is cut to the window and its length with it; interior texels get the node's
 * bytes. Into cm->nbuf (w·h·2), then the normal slice. */
static void derive_rect(struct view_clipmap *cm, struct level *L, int level,
			const struct grid_quad *q, int64_t u0, int64_t v0, uint32_t w, uint32_t h)
{
	const uint32_t T = cm->T, S = cm->S;
	const uint64_t t0 = clock_now_ns();
	const int64_t W = (int64_t)grid_tiles_x(q->lx) * T, H = (int64_t)grid_tiles_y(q->ly) * T;
	const bool ring = (int64_t)q->w >= W; /* the window holds whole parallels */
	const double dlam = 2 * M_PI / (double)W, dphi = M_PI / (double)H;
	uint64_t quarter = (uint64_t)W / 4;
	uint32_t kmax = quarter < T ? (uint32_t)(quarter > 0 ? quarter : 1) : T;
	const int64_t du0 = wrap_u(u0 - q->u0, W); /* room west of the first texel */
	if (!L->nrp) {
		L->nrp = xmalloc((size_t)S * sizeof *L->nrp);
		for (uint32_t i = 0; i < S; i++)
			L->nrp[i].v = -1;
	}
	/* each row's stencil figures (cached by row), and the widest east stencil among them */
	uint32_t kneed = 1;
	for (uint32_t j = 0; j < h; j++) {
		int64_t v = v0 + j;
		struct nrow_par *P = &L->nrp[v % S];
		if (P->v != v || P->lx != q->lx) {
			double lat = grid_v_to_lat(q->ly, T, (double)v + 0.5), mrad, nrad;
			geo_radii(cm->body, lat, &mrad, &nrad);
			P->v = v;
			P->lx = q->lx;
			P->dy = mrad * dphi;
			P->r = nrad * cos(lat * (M_PI / 180.0));
			P->k = normalmap_east_stencil(P->r, dlam, P->dy, kmax, &P->len);
		}
		kneed = P->k > kneed ? P->k : kneed;
	}
	/* the mirror's column of level texel u0 + i − kmax, and half a turn round (across a
	 * pole), for i in [kmax − kneed, kmax + w + kneed): the stencils' reach (a thin strip
	 * far from a pole needs w + 2 columns, not the w + 2·kmax a pole row could) */
	uint32_t *col = cm->ncol, *colp = cm->ncol + (w + 2 * (size_t)kmax);
	int64_t uc = wrap_u(u0 - kneed, W), up2 = wrap_u(u0 - kneed + W / 2, W);
	for (uint32_t i = kmax - kneed; i < kmax + w + kneed; i++) {
		col[i] = (uint32_t)(uc % S);
		colp[i] = (uint32_t)(up2 % S);
		uc = uc + 1 == W ? 0 : uc + 1;
		up2 = up2 + 1 == W ? 0 : up2 + 1;
	}
	for (uint32_t j = 0; j < h; j++) {
		int64_t v = v0 + j;
		const struct nrow_par *P = &L->nrp[v % S];
		const double dy = P->dy, r = P->r, len = P->len;
		const uint32_t k = P->k;
		float fx = (float)(1.0 / len);
		bool has_n = v > q->v0, has_s = v + 1 < q->v0 + (int64_t)q->h;
		bool over_n = v == 0 && ring, over_s = v == H - 1 && ring;
		float fy = (has_n || over_n) && (has_s || over_s) ? (float)(1.0 / (2 * dy))
								  : (float)(1.0 / dy);
		const float *row = L->hmirror + (size_t)(v % S) * S;
		const float *rn = has_n ? L->hmirror + (size_t)((v - 1) % S) * S : row;
		const float *rs = has_s ? L->hmirror + (size_t)((v + 1) % S) * S : row;
		const uint32_t *cn = has_n || !over_n ? col : colp, *cs = has_s || !over_s ? col : colp;
		uint8_t *out = cm->nbuf + (size_t)j * w * 2;
		/* the stencils' heights gathered into rows, then normalmap_row over them all
		 * with the row's east stencil; texels whose stencil the window cuts (only when
		 * it does not hold whole parallels) are made again with their own */
		float *we = cm->nrow, *ea = we + w, *nu = ea + w, *sd = nu + w;
		for (uint32_t i = 0; i < w; i++) {
			uint32_t c = i + kmax; /* this texel in col */
			float ctr = row[col[c]];
			we[i] = row[col[c - k]];
			ea[i] = row[col[c + k]];
			nu[i] = has_n || over_n ? rn[cn[c]] : ctr;
			sd[i] = has_s || over_s ? rs[cs[c]] : ctr;
		}
		normalmap_row(we, ea, nu, sd, fx, fy, out, w);
		if (!ring) { /* west of wend the west end is cut, from estart the east end */
			int64_t wend = k - du0, estart = (int64_t)q->w - du0 - k;
			wend = wend < 0 ? 0 : wend < (int64_t)w ? wend : (int64_t)w;
			estart = estart < wend ? wend : estart < (int64_t)w ? estart : (int64_t)w;
			for (int64_t i = 0; i < wend; i++)
				derive_cut(q, du0 + i, k, r, dlam, fy, row, col, (uint32_t)i + kmax,
					   nu[i], sd[i], out + 2 * i);
			for (int64_t i = estart; i < (int64_t)w; i++)
				derive_cut(q, du0 + i, k, r, dlam, fy, row, col, (uint32_t)i + kmax,
					   nu[i], sd[i], out + 2 * i);
		}
	}
	cm->st.normals_derived += (uint64_t)w * h;
	cm->st.derive_ns += clock_now_ns() - t0;
	upload_normals(cm, level, W, u0, v0, w, h, cm->nbuf);
}

/* After region g of the heights changed: its normals and those of the texels round it
 * (their stencils reach into it), inside the window. */
static void derive_region(struct view_clipmap *cm, struct level *L, int level,
			  const struct grid_quad *q, const struct grid_region *g)
{
	const int64_t W = (int64_t)grid_tiles_x(q->lx) * cm->T;
	int64_t ua = (int64_t)g->tx * cm->T + g->sx - 1, ub = ua + g->w + 2;
	int64_t va = (int64_t)g->ty * cm->T + g->sy - 1, vb = va + g->h + 2;
	if (va < q->v0)
		va = q->v0;
	if (vb > q->v0 + (int64_t)q->h)
		vb = q->v0 + (int64_t)q->h;
	if ((int64_t)q->w < W) { /* not the whole parallel: stay inside the window */
		if (wrap_u(ua - q->u0, W) >= (int64_t)q->w)
			ua++;
		if (wrap_u(ub - 1 - q->u0, W) >= (int64_t)q->w)
			ub--;
	} else if (ub - ua > W) {
		ub = ua + W;
	}
	if (ub > ua && vb > va)
		derive_rect(cm, L, level, q, ua, va, (uint32_t)(ub - ua), (uint32_t)(vb - va));
}

/* Copies into the level's textures the regions of window `to` that the held window lacks
 * (the colour: all of `to` when its slice is stale), if every tile they copy from is here,
 * for every role; `to` is then held. Returns 1, or 0 (a tile missing: nothing copied). */
static int upload_window(struct view_clipmap *cm, int level, const struct grid_quad *to,
			 bool stale)
{
	struct level *L = &cm->lv[level];
	/* Heights and normals: the regions the held window lacks. Colour after a layer switch:
	 * the whole target from the new layer at once, so a slice never holds two layers. */
	struct grid_region rg[GRID_MAX_REGIONS], whole[GRID_MAX_REGIONS];
	int nr = grid_update_regions(L->has_held ? &L->held : NULL, to, rg);
	const struct grid_region *crg = stale ? whole : rg; /* the colour's regions */
	int ncr = stale ? grid_update_regions(NULL, to, whole) : nr;
	/* Every tile a region copies from must be here, for every role. */
	for (int r = 0; r < VIEW_NROLES; r++) {
		const struct grid_region *g = r == VIEW_COLOR ? crg : rg;
		for (int i = 0; cm->layer[r] >= 0 && i < (r == VIEW_COLOR ? ncr : nr); i++) {
			struct tile_key k = { 0, g[i].tx, g[i].ty, to->lx, to->ly };
			if (!find(L, r, &k))
				return 0;
		}
	}
	const struct gl *gl = cm->gl;
	uint32_t T = cm->T, period = level_period(cm, to);
	gl->PixelStorei(GL_UNPACK_ALIGNMENT, 1);
	gl->PixelStorei(GL_UNPACK_ROW_LENGTH, (GLint)T);
	for (int r = 0; r < VIEW_NROLES; r++) {
		if (cm->layer[r] < 0)
			continue;
		size_t bpp = pix_bytes(roles[r].type);
		const struct grid_region *rgr = r == VIEW_COLOR ? crg : rg;
		int nrr = r == VIEW_COLOR ? ncr : nr;
		gl->BindTexture(GL_TEXTURE_2D_ARRAY, cm->tex[r]);
		for (int i = 0; i < nrr; i++) {
			const struct grid_region *g = &rgr[i];
			struct tile_key k = { 0, g->tx, g->ty, to->lx, to->ly };
			const struct slot *s = find(L, r, &k);
			const unsigned char *base = s->t.texels ? s->t.texels : cm->zeros;
			for (uint32_t x = g->x; x < cm->S; x += period) {
				gl->TexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, (GLint)x, (GLint)g->y, level,
						  (GLsizei)g->w, (GLsizei)g->h, 1, roles[r].fmt,
						  roles[r].gltype,
						  base + ((size_t)g->sy * T + g->sx) * bpp);
				cm->st.bytes_uploaded += (uint64_t)g->w * g->h * bpp;
				cm->st.regions_uploaded++;
			}
			if (r == VIEW_HEIGHT)
				mirror_region(cm, L, g, base, period);
			if (r == VIEW_COLOR && cm->keep_alpha)
				mirror_alpha(cm, L, g, base, period);
		}
		/* Derived normals once the heights are in the mirror — here, before the colour:
		 * each role leaves its texture bound on the active unit, and the colour's must
		 * be the last (a frame that uploads draws with the bindings as they are). */
		if (r == VIEW_HEIGHT && cm->derive) {
			gl->BindTexture(GL_TEXTURE_2D_ARRAY, cm->tex[VIEW_NORMAL]);
			for (int i = 0; i < nr; i++)
				derive_region(cm, L, level, to, &rg[i]);
		}
	}
	gl->PixelStorei(GL_UNPACK_ROW_LENGTH, 0);
	L->held = *to;
	L->has_held = true;
	L->cgen = cm->cgen;
	return 1;
}

/* How far (texels) window q reaches round the middle of target: the least distance from it
 * to q's edges (columns unbounded where q holds whole parallels, rows where it reaches the
 * level's edge); negative when the middle is outside q. */
static double window_reach(const struct grid_quad *q, const struct grid_quad *target)
{
	int64_t W = (int64_t)grid_tiles_x(q->lx) * q->T, H = (int64_t)grid_tiles_y(q->ly) * q->T;
	if (q->lx != target->lx || q->ly != target->ly)
		return -INFINITY;
	double cu = (double)target->u0 + target->w / 2.0, cv = (double)target->v0 + target->h / 2.0;
	double r = INFINITY;
	if ((int64_t)q->w < W) {
		double du = grid_window_rel_u(q, cu);
		r = fmin(du, (double)q->w - du);
	}
	if (q->v0 > 0)
		r = fmin(r, cv - (double)q->v0);
	if (q->v0 + (int64_t)q->h < H)
		r = fmin(r, (double)q->v0 + q->h - cv);
	return r;
}

int view_clipmap_update(struct view_clipmap *cm, int level)
{
	struct level *L = &cm->lv[level];
	if (!L->has_target)
		return 0;
	bool stale = view_clipmap_color_stale(cm, level);
	if (L->has_held && grid_quad_equal(&L->held, &L->target) && !stale)
		return 1;
	if (upload_window(cm, level, &L->target, stale))
		return 1;
	/* The target is not all here: its core (the middle half of the window, then the middle
	 * quarter), as soon as the tiles of one are, where it reaches farther round the
	 * target's middle than the held window does (never a step back: a held window that
	 * holds the core, as after a move of a tile, stays). The level's own ring needs the
	 * quarter (a radius of 3/8 of a tile), the ring it gives detail to the half, only the
	 * ring two coarser the whole window (common/clipmap.h): with the tiles asked for from
	 * the middle out (view_clipmap_wants) a level is drawn after 1-4 tiles of each layer
	 * instead of 16-25. Not during a colour switch (the slice is refilled whole). */
	double held_reach = L->has_held ? window_reach(&L->held, &L->target) : -INFINITY;
	for (uint32_t w = cm->S / 2; !stale && w >= cm->T; w /= 2) {
		struct grid_quad core;
		grid_window_core(&L->target, w, &core);
		if (grid_quad_equal(&core, &L->target) || window_reach(&core, &L->target) <= held_reach)
			break;
		if (upload_window(cm, level, &core, false))
			break;
	}
	return 0;
}

const struct grid_quad *view_clipmap_held(const struct view_clipmap *cm, int level)
{
	return cm->lv[level].has_held ? &cm->lv[level].held : NULL;
}

const struct grid_quad *view_clipmap_target_of(const struct view_clipmap *cm, int level)
{
	return cm->lv[level].has_target ? &cm->lv[level].target : NULL;
}

/* The finest level whose held window covers (lon, lat) and has a mirror (the alpha mirror with
 * alpha, else the heights'): its four texels round the point and their bilinear weights.
 * Returns NULL where none. */
static const struct level *mirror_taps(const struct view_clipmap *cm, double lon, double lat,
				       bool alpha, size_t at[4], double w[4])
{
	int64_t S = cm->S;
	for (int l = cm->nlevels - 1; l >= 0; l--) {
		const struct level *L = &cm->lv[l];
		if (!L->has_held || !(alpha ? (void *)L->amirror : (void *)L->hmirror) ||
		    !view_window_covers(&L->held, lon, lat, 0, 1))
			continue;
		double p[6];
		view_level_params(&L->held, lon, lat, p);
		double x = p[0] - 0.5, y = fmin(fmax(p[1], p[4]), p[5]) - 0.5;
		double fx = floor(x), fy = floor(y), ax = x - fx, ay = y - fy;
		int64_t x0 = (int64_t)fx, y0 = (int64_t)fy;
		for (int j = 0; j < 2; j++)
			for (int i = 0; i < 2; i++) {
				int64_t xi = ((x0 + i) % S + S) % S, yj = ((y0 + j) % S + S) % S;
				at[2 * j + i] = (size_t)yj * (size_t)S + (size_t)xi;
				w[2 * j + i] = (j ? ay : 1 - ay) * (i ? ax : 1 - ax);
			}
		return L;
	}
	return NULL;
}

int view_clipmap_ground(const struct view_clipmap *cm, double lon, double lat, double *h)
{
	size_t at[4];
	double w[4];
	const struct level *L = mirror_taps(cm, lon, lat, false, at, w);
	if (!L)
		return -ENOENT;
	*h = 0;
	for (int k = 0; k < 4; k++)
		*h += w[k] * L->hmirror[at[k]];
	return 0;
}

int view_clipmap_alpha(const struct view_clipmap *cm, double lon, double lat, double *a)
{
	size_t at[4];
	double w[4];
	const struct level *L = mirror_taps(cm, lon, lat, true, at, w);
	if (!L)
		return -ENOENT;
	*a = 0;
	for (int k = 0; k < 4; k++)
		*a += w[k] * L->amirror[at[k]] / 255.0;
	return 0;
}

unsigned view_clipmap_texture(const struct view_clipmap *cm, enum view_role r) { return cm->tex[r]; }

int view_clipmap_read(const struct view_clipmap *cm, enum view_role r, void *out, size_t size)
{
	if (!cm->tex[r] || size < (size_t)cm->S * cm->S * cm->nlevels * pix_bytes(roles[r].type))
		return -ENOENT;
	const struct gl *gl = cm->gl;
	gl->PixelStorei(GL_PACK_ALIGNMENT, 1);
	gl->BindTexture(GL_TEXTURE_2D_ARRAY, cm->tex[r]);
	gl->GetTexImage(GL_TEXTURE_2D_ARRAY, 0, roles[r].fmt, roles[r].gltype, out);
	return 0;
}

uint32_t view_clipmap_tile_size(const struct view_clipmap *cm) { return cm->T; }
uint32_t view_clipmap_window_size(const struct view_clipmap *cm) { return cm->S; }
int view_clipmap_levels(const struct view_clipmap *cm) { return cm->nlevels; }

void view_clipmap_get_stats(const struct view_clipmap *cm, struct view_clipmap_stats *out)
{
	*out = cm->st;
}

int view_clipmap_height_range(struct view_clipmap *cm, int level, double *lo, double *hi)
{
	struct level *L = &cm->lv[level];
	if (!L->has_held || !L->hmirror)
		return -ENOENT;
	if (L->hdirty) {
		/* The whole slice, stale texels included: whatever the shader can sample. */
		const float *h = L->hmirror;
		size_t n = (size_t)cm->S * cm->S;
		float a = h[0], b = h[0];
		for (size_t i = 1; i < n; i++) {
			a = h[i] < a ? h[i] : a;
			b = h[i] > b ? h[i] : b;
		}
		L->hlo = a;
		L->hhi = b;
		L->hdirty = false;
	}
	*lo = L->hlo;
	*hi = L->hhi;
	return 0;
}

/* The range of heights over texels [u0, u1] × [v0, v1] of the slice (u wraps, v in 0..S-1). */
static void texel_range(const struct view_clipmap *cm, const float *h, int64_t u0, int64_t u1,
			int64_t v0, int64_t v1, float *lo, float *hi)
{
	int64_t S = cm->S;
	float a = INFINITY, b = -INFINITY;
	int64_t s0 = ((u0 % S) + S) % S, n = u1 - u0 + 1;
	for (int64_t y = v0; y <= v1; y++) {
		const float *row = h + (size_t)(((y % S) + S) % S) * (size_t)S;
		/* the row's span in at most two pieces (the torus' seam) */
		for (int64_t x = s0, left = n; left > 0;) {
			int64_t run = S - x < left ? S - x : left;
			for (int64_t k = 0; k < run; k++) {
				a = row[x + k] < a ? row[x + k] : a;
				b = row[x + k] > b ? row[x + k] : b;
			}
			left -= run;
			x = 0;
		}
	}
	*lo = a;
	*hi = b;
}

int view_clipmap_height_range_box(struct view_clipmap *cm, int level, double x0, double x1,
				  double y0, double y1, double *lo, double *hi)
{
	struct level *L = &cm->lv[level];
	if (!L->has_held || !L->hmirror)
		return -ENOENT;
	/* Texel centres sit at +0.5: a sample at x reads texels floor(x - 0.5) and the next; a
	 * texel more on each side for the shader's float rounding. */
	int64_t u0 = (int64_t)floor(x0 - 0.5) - 1, u1 = (int64_t)floor(x1 - 0.5) + 2;
	int64_t v0 = (int64_t)floor(y0 - 0.5) - 1, v1 = (int64_t)floor(y1 - 0.5) + 2;
	if (!(u1 - u0 + 1 < (int64_t)cm->S && v1 - v0 + 1 < (int64_t)cm->S))
		return view_clipmap_height_range(cm, level, lo, hi);
	float a, b;
	texel_range(cm, L->hmirror, u0, u1, v0, v1, &a, &b);
	*lo = a;
	*hi = b;
	return 0;
}

int view_clipmap_height_range_near(struct view_clipmap *cm, int level, double lon, double lat,
				   double r, double *lo, double *hi)
{
	struct level *L = &cm->lv[level];
	if (!L->has_held || !L->hmirror)
		return -ENOENT;
	for (int k = 0; k < 2; k++) {
		const struct near_range *c = &L->near[k];
		if (c->hver == L->hver && c->lon == lon && c->lat == lat && c->r == r) {
			*lo = c->lo;
			*hi = c->hi;
			return 0;
		}
	}
	double ext = clipmap_lon_extent(lat, r);
	if (ext >= M_PI || !view_window_covers(&L->held, lon, lat, r, 1.5))
		return view_clipmap_height_range(cm, level, lo, hi);
	double p[6];
	view_level_params(&L->held, lon, lat, p);
	double du = ext * p[2], dv = r * p[3];
	int rc = view_clipmap_height_range_box(cm, level, p[0] - du, p[0] + du,
					       fmax(p[1] - dv, p[4]), fmin(p[1] + dv, p[5]), lo, hi);
	if (rc == 0)
		L->near[L->near_next] = (struct near_range){ lon, lat, r, L->hver, (float)*lo,
							     (float)*hi };
	L->near_next ^= 1;
	return rc;
}

uint64_t view_clipmap_height_version(const struct view_clipmap *cm, int level)
{
	return cm->lv[level].hver;
}

bool view_clipmap_color_stale(const struct view_clipmap *cm, int level)
{
	const struct level *L = &cm->lv[level];
	return L->has_held && cm->layer[VIEW_COLOR] >= 0 && L->cgen != cm->cgen;
}

int view_clipmap_color_find(const struct view_clipmap *cm, const char *name)
{
	const struct view_planet *p = &cm->src->planet;
	for (int i = 0; i < p->nlayers; i++)
		if (p->layer[i].format == PIX_COLOR && !strcmp(p->layer[i].name, name))
			return i;
	return -1;
}

int view_clipmap_color_layer(const struct view_clipmap *cm) { return cm->layer[VIEW_COLOR]; }

int view_clipmap_set_color(struct view_clipmap *cm, int layer)
{
	const struct view_planet *p = &cm->src->planet;
	if (cm->layer[VIEW_COLOR] < 0 || layer < 0 || layer >= p->nlayers ||
	    p->layer[layer].format != PIX_COLOR)
		return -EINVAL;
	if (layer == cm->layer[VIEW_COLOR])
		return 0;
	/* The old layer's tiles go (those still in flight are dropped as they arrive: no role
	 * takes their layer); each held level keeps its slice until the new one is complete. */
	for (int l = 0; l < cm->nlevels; l++)
		for (int i = 0; i < SLOTS; i++)
			drop(cm, &cm->lv[l].slots[VIEW_COLOR][i]);
	cm->layer[VIEW_COLOR] = layer;
	cm->cgen++;
	return 1;
}
