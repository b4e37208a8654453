/* render — see render.h. Tiles are fetched in batches through sched_fetch so memory stays
 * bounded and progress can be reported; each tile is copied into the picture as it comes. */
#include "render.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "engine/cache.h"
#include "engine/sched.h"

#define MAX_PIXELS_WIDE 32768
#define BATCH 32

static const struct planet_layer *normal_layer(const struct planet *p)
{
	for (size_t i = 0; i < p->nlayers; i++)
		if (p->layers[i].type == PIX_NORMAL)
			return &p->layers[i];
	return NULL;
}

/* Multiplies colour by a hillshade, as maps do: sun from the north-west 35° up, slopes
 * exaggerated 3× (a map's z-factor). Flat ground keeps its colour; slopes facing the sun
 * brighten, the others darken. */
static void shade_tile(unsigned char *rgba, const unsigned char *rg, size_t n)
{
	const double el = 35.0 * M_PI / 180.0, zf = 3.0;
	const double lx = -cos(el) * M_SQRT1_2, ly = cos(el) * M_SQRT1_2, lz = sin(el);
	for (size_t i = 0; i < n; i++) {
		double e = rg[2 * i] / 127.5 - 1.0, no = rg[2 * i + 1] / 127.5 - 1.0;
		double up2 = 1.0 - e * e - no * no;
		double up = up2 > 0 ? sqrt(up2) : 0.0;
		/* scale the slope (e/up, no/up) by zf and renormalise */
		double se = e * zf, sn = no * zf;
		double len = sqrt(se * se + sn * sn + up * up);
		if (len > 0) {
			e = se / len;
			no = sn / len;
			up = up / len;
		}
		double f = (e * lx + no * ly + up * lz) / lz;
		f = 0.35 + 0.65 * f;
		if (f < 0.25)
			f = 0.25;
		if (f > 1.6)
			f = 1.6;
		for (int c = 0; c < 3; c++) {
			double v = rgba[4 * i + c] * f;
			rgba[4 * i + c] = (unsigned char)(v > 255 ? 255 : v + 0.5);
		}
	}
}

static void blit(struct render_image *im, const struct tile *t, const struct tile *shade,
		 uint32_t col, uint32_t row)
{
	uint32_t T = t->size;
	size_t n = (size_t)T * T;
	unsigned char *tmp = NULL;
	const unsigned char *src = t->data;
	if (t->type == PIX_COLOR && shade) {
		tmp = xmalloc(t->nbytes);
		memcpy(tmp, t->data, t->nbytes);
		shade_tile(tmp, shade->data, n);
		src = tmp;
	}
	for (uint32_t j = 0; j < T; j++) {
		size_t y = (size_t)row * T + j;
		size_t x0 = (size_t)col * T;
		if (t->type == PIX_HEIGHT) {
			float *dst = (float *)im->pixels + y * (size_t)im->width + x0;
			const float *s = (const float *)(const void *)src + (size_t)j * T;
			memcpy(dst, s, T * sizeof(float));
			for (uint32_t i = 0; i < T; i++) {
				if (s[i] < im->hmin)
					im->hmin = s[i];
				if (s[i] > im->hmax)
					im->hmax = s[i];
			}
		} else if (t->type == PIX_COLOR) {
			unsigned char *dst = (unsigned char *)im->pixels + (y * (size_t)im->width + x0) * 4;
			memcpy(dst, src + (size_t)j * T * 4, (size_t)T * 4);
		} else {
			unsigned char *dst = (unsigned char *)im->pixels + (y * (size_t)im->width + x0) * 3;
			pix_normals_rgb(src + (size_t)j * T * 2, dst, T);
		}
	}
	free(tmp);
}

void render_region_level(int lx, int ly, struct render_region *r)
{
	*r = (struct render_region){ .lx = lx, .ly = ly, .cols = grid_tiles_x(lx),
				     .rows = grid_tiles_y(ly) };
}

int render_lx_at(int ly, double lat)
{
	/* a texel of level (ly + 1, ly) is as wide as tall at the equator; its width shrinks
	 * with cos(lat), so halve the columns once per halving of that */
	double c = cos(fmin(fabs(lat), 90.0) * (M_PI / 180.0));
	int lx = ly + 1 + (c > 1e-9 ? (int)lround(log2(c)) : -(ly + 1));
	return lx < 0 ? 0 : lx;
}

void render_region_around(int lx, int ly, double lat, double lon, uint32_t n,
			  struct render_region *r)
{
	uint32_t nx = grid_tiles_x(lx), ny = grid_tiles_y(ly);
	if (n > ny)
		n = ny;
	int64_t cx = (int64_t)floor(grid_lon_to_u(lx, 1, lon));
	int64_t cy = (int64_t)floor(grid_lat_to_v(ly, 1, lat));
	int64_t y0 = cy - (int64_t)(n - 1) / 2;
	if (y0 < 0)
		y0 = 0;
	if (y0 + n > ny)
		y0 = ny - n;
	r->lx = lx;
	r->ly = ly;
	r->x = grid_wrap_x(lx, cx - (int64_t)(n - 1) / 2);
	r->y = (uint32_t)y0;
	r->cols = n < nx ? n : nx;
	r->rows = n;
}

int render_layer(const struct planet *p, const char *layer, const struct render_region *rg,
		 const struct render_opts *o, struct render_image *out, char err[256])
{
	int lx = rg->lx, ly = rg->ly;
	memset(out, 0, sizeof *out);
	const struct planet_layer *L = planet_find_layer(p, layer);
	if (!L) {
		char names[160] = "";
		for (size_t i = 0; i < p->nlayers; i++) {
			size_t l = strlen(names);
			snprintf(names + l, sizeof names - l, "%s%s", i ? ", " : "", p->layers[i].name);
		}
		err_set(err, "planet %s has no layer \"%s\" (layers: %s)", p->name, layer, names);
		return -ENOENT;
	}
	if (!grid_level_valid(lx, ly) || ly > p->max_level) {
		err_set(err, "level (%d, %d) is not valid for planet %s: need 0 <= ly <= %d and "
			"0 <= lx <= ly + 1", lx, ly, p->name, p->max_level);
		return -EINVAL;
	}
	uint32_t T = p->tile_size;
	uint32_t cols = rg->cols, rows = rg->rows;
	if (rg->x >= grid_tiles_x(lx) || rg->y >= grid_tiles_y(ly) || rows == 0 || cols == 0 ||
	    cols > grid_tiles_x(lx) || rg->y + rows > grid_tiles_y(ly)) {
		err_set(err, "tiles (%u, %u) + %ux%u are outside level (%d, %d): x < %u, y < %u",
			rg->x, rg->y, cols, rows, lx, ly, grid_tiles_x(lx), grid_tiles_y(ly));
		return -EINVAL;
	}
	if ((uint64_t)cols * T > MAX_PIXELS_WIDE) {
		err_set(err, "level (%d, %d) is %llu pixels wide: more than %d; pick a coarser "
			"level or single tiles", lx, ly, (unsigned long long)cols * T, MAX_PIXELS_WIDE);
		return -E2BIG;
	}
	const struct planet_layer *NL = (o->shade && L->type == PIX_COLOR) ? normal_layer(p) : NULL;
	if (o->shade && L->type == PIX_COLOR && !NL) {
		err_set(err, "--shade needs a normal layer; planet %s has none", p->name);
		return -EINVAL;
	}
	out->width = (int)(cols * T);
	out->height = (int)(rows * T);
	out->georef = 1;
	out->bounds = (struct geo_rect){ .west = grid_u_to_lon(lx, T, (double)rg->x * T),
					 .east = grid_u_to_lon(lx, T, (double)(rg->x + cols) * T),
					 .north = grid_v_to_lat(ly, T, (double)rg->y * T),
					 .south = grid_v_to_lat(ly, T, (double)(rg->y + rows) * T) };
	out->channels = L->type == PIX_HEIGHT ? 1 : L->type == PIX_COLOR ? 4 : 3;
	out->is_float = L->type == PIX_HEIGHT;
	out->hmin = INFINITY;
	out->hmax = -INFINITY;
	size_t px = (size_t)out->width * out->height;
	out->pixels = xmalloc(px * (out->is_float ? 4 : (size_t)out->channels));

	struct cache *c = cache_create((o->cache_mb ? o->cache_mb : 1024) << 20);
	struct sched *s = sched_create(
		&(struct sched_desc){ .cache = c, .workers = o->workers, .store = o->store });
	size_t total = (size_t)cols * rows, done = 0;
	int rc = 0;
	struct want w[2 * BATCH];
	struct tile *tiles[2 * BATCH];
	while (done < total && rc == 0) {
		size_t n = total - done < BATCH ? total - done : BATCH;
		for (size_t i = 0; i < n; i++) {
			size_t idx = done + i;
			struct tile_key k = { .node = L->node->hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly };
			k.x = grid_wrap_x(lx, (int64_t)rg->x + (int64_t)(idx % cols));
			k.y = rg->y + (uint32_t)(idx / cols);
			w[i] = (struct want){ .node = L->node, .key = k, .cls = SCHED_VISIBLE };
			if (NL) {
				w[n + i] = w[i];
				w[n + i].node = NL->node;
				w[n + i].key.node = NL->node->hash;
			}
		}
		size_t nw = NL ? 2 * n : n;
		rc = sched_fetch(s, w, nw, tiles);
		if (rc) {
			err_set(err, "generating %s tile (%d, %d, %u, %u) of planet %s: %s", layer,
				lx, ly, w[0].key.x, w[0].key.y, p->name, strerror(-rc));
		} else {
			for (size_t i = 0; i < n; i++)
				blit(out, tiles[i], NL ? tiles[n + i] : NULL,
				     (uint32_t)((done + i) % cols), (uint32_t)((done + i) / cols));
		}
		for (size_t i = 0; i < nw; i++)
			tile_unref(tiles[i]);
		done += n;
		if (o->progress)
			o->progress(o->ud, done, total);
	}
	sched_destroy(s);
	cache_destroy(c);
	if (rc)
		render_image_free(out);
	return rc;
}
