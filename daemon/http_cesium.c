/* http_cesium — see http_cesium.h. The byte layout (little-endian) of quantized-mesh-1.0:
 * header (88 bytes: centre xyz, min and max height, bounding sphere xyzr, horizon occlusion
 * point xyz), vertex data (count, then u, v and height arrays of uint16, each zigzag-delta
 * coded, u and v in [0, 32767] west→east and south→north, height in [0, 32767] from min to
 * max), triangle indices (count, then 16-bit "high-water mark" coded indices: vertices are
 * numbered in the order triangles first use them), then the vertices on the west, south, east
 * and north edges (count + plain 16-bit indices each); then the extensions asked for, each
 * an id byte, a uint32 length and its data: octvertexnormals (id 1) is 2 bytes per vertex,
 * in vertex order. */
#include "http_cesium.h"

#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "common/grid.h"
#include "common/strbuf.h"
#include "common/xalloc.h"

const struct planet_layer *cesium_normal_layer(const struct planet *p,
					       const struct planet_layer *heights)
{
	for (size_t i = 0; heights && i < p->nlayers; i++) {
		const struct node *n = p->layers[i].node;
		if (p->layers[i].type == PIX_NORMAL && n->type && !strcmp(n->type->name, "normal") &&
		    n->in[0] == heights->node)
			return &p->layers[i];
	}
	return NULL;
}

char *cesium_layer_json(const struct planet *p, bool normals, size_t *len)
{
	struct strbuf b = { 0 };
	strbuf_printf(&b, "{\n  \"tilejson\": \"2.1.0\",\n  \"name\": ");
	strbuf_json(&b, p->name);
	strbuf_printf(&b, ",\n");
	if (normals)
		strbuf_printf(&b, "  \"extensions\": [\"octvertexnormals\"],\n");
	strbuf_printf(&b, "  \"version\": \"1.0.0\",\n  \"format\": \"quantized-mesh-1.0\",\n"
			  "  \"scheme\": \"tms\",\n  \"tiles\": [\"{z}/{x}/{y}.terrain\"],\n"
			  "  \"projection\": \"EPSG:4326\",\n  \"bounds\": [-180, -90, 180, 90],\n"
			  "  \"minzoom\": 0,\n  \"maxzoom\": %d,\n  \"available\": [\n",
		      p->max_level);
	for (int z = 0; z <= p->max_level; z++)
		strbuf_printf(&b, "    [{\"startX\": 0, \"startY\": 0, \"endX\": %.0f, \"endY\": %.0f}]%s\n",
			      ldexp(1, z + 1) - 1, ldexp(1, z) - 1, z < p->max_level ? "," : "");
	strbuf_printf(&b, "  ]\n}\n");
	return strbuf_take(&b, len);
}

struct out {
	unsigned char *b;
	size_t n, cap;
};

static void put(struct out *o, const void *v, size_t n)
{
	if (o->n + n > o->cap) {
		o->cap = (o->n + n) * 2;
		o->b = xrealloc(o->b, o->cap);
	}
	memcpy(o->b + o->n, v, n); /* x86-64 and every target we build for are little-endian */
	o->n += n;
}

static void put_u32(struct out *o, uint32_t v) { put(o, &v, 4); }
static void put_u16(struct out *o, uint16_t v) { put(o, &v, 2); }
static void put_f64(struct out *o, double v) { put(o, &v, 8); }
static void put_f32(struct out *o, float v) { put(o, &v, 4); }

/* Geodetic (degrees, metres above the ellipsoid a, f) → Earth-centred, Earth-fixed. */
static void ecef(double a, double f, double lat, double lon, double h, double out[3])
{
	double e2 = f * (2 - f), sp = sin(lat * M_PI / 180), cp = cos(lat * M_PI / 180);
	double N = a / sqrt(1 - e2 * sp * sp);
	out[0] = (N + h) * cp * cos(lon * M_PI / 180);
	out[1] = (N + h) * cp * sin(lon * M_PI / 180);
	out[2] = (N * (1 - e2) + h) * sp;
}

/* (v << 1) ^ (v >> 31) in unsigned arithmetic (a negative int shifted left is undefined). */
static uint16_t zigzag(int v)
{
	return (uint16_t)(v < 0 ? ((uint32_t)-(int64_t)v << 1) - 1 : (uint32_t)v << 1);
}

/* Height at texel-corner (i, j) of a T×T tile, bilinear between texel centres, clamped. */
static double corner_height(const float *h, uint32_t T, double x, double y)
{
	x -= 0.5;
	y -= 0.5;
	x = x < 0 ? 0 : x > T - 1 ? T - 1 : x;
	y = y < 0 ? 0 : y > T - 1 ? T - 1 : y;
	uint32_t x0 = (uint32_t)x, y0 = (uint32_t)y;
	uint32_t x1 = x0 + 1 < T ? x0 + 1 : x0, y1 = y0 + 1 < T ? y0 + 1 : y0;
	double fx = x - x0, fy = y - y0;
	double a = h[(size_t)y0 * T + x0] * (1 - fx) + h[(size_t)y0 * T + x1] * fx;
	double b = h[(size_t)y1 * T + x0] * (1 - fx) + h[(size_t)y1 * T + x1] * fx;
	return a * (1 - fy) + b * fy;
}

/* Unit normal at texel-corner (x, y) of normal tile nt (RG8: east, north; up implied),
 * bilinear between texel centres as corner_height, in the local east-north-up frame. */
static void corner_normal(const uint8_t *rg, uint32_t T, double x, double y, double enu[3])
{
	x -= 0.5;
	y -= 0.5;
	x = x < 0 ? 0 : x > T - 1 ? T - 1 : x;
	y = y < 0 ? 0 : y > T - 1 ? T - 1 : y;
	uint32_t x0 = (uint32_t)x, y0 = (uint32_t)y;
	uint32_t xs[2] = { x0, x0 + 1 < T ? x0 + 1 : x0 }, ys[2] = { y0, y0 + 1 < T ? y0 + 1 : y0 };
	double fx = x - x0, fy = y - y0, w[4] = { (1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy,
						 fx * fy };
	enu[0] = enu[1] = enu[2] = 0;
	for (int k = 0; k < 4; k++) {
		const uint8_t *c = rg + 2 * ((size_t)ys[k / 2] * T + xs[k % 2]);
		double e = c[0] / 127.5 - 1, n = c[1] / 127.5 - 1, u2 = 1 - e * e - n * n;
		enu[0] += w[k] * e;
		enu[1] += w[k] * n;
		enu[2] += w[k] * (u2 > 0 ? sqrt(u2) : 0);
	}
	double m = sqrt(enu[0] * enu[0] + enu[1] * enu[1] + enu[2] * enu[2]);
	if (!(m > 0)) {
		enu[0] = enu[1] = 0;
		enu[2] = m = 1;
	}
	for (int j = 0; j < 3; j++)
		enu[j] /= m;
}

/* Cesium's AttributeCompression.octEncode (range 255) of unit vector v: 2 bytes. */
static void oct_encode(const double v[3], uint8_t out[2])
{
	double l1 = fabs(v[0]) + fabs(v[1]) + fabs(v[2]);
	double x = v[0] / l1, y = v[1] / l1;
	if (v[2] < 0) {
		double ox = x;
		x = (1 - fabs(y)) * (ox >= 0 ? 1 : -1);
		y = (1 - fabs(ox)) * (y >= 0 ? 1 : -1);
	}
	x = x < -1 ? -1 : x > 1 ? 1 : x;
	y = y < -1 ? -1 : y > 1 ? 1 : y;
	out[0] = (uint8_t)lround((x * 0.5 + 0.5) * 255);
	out[1] = (uint8_t)lround((y * 0.5 + 0.5) * 255);
}

/* Cesium's horizon-culling magnitude of point p (scaled space) along unit direction d. */
static double occlusion_magnitude(const double p[3], const double d[3])
{
	double m2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2], m = sqrt(m2);
	double dir[3] = { p[0] / m, p[1] / m, p[2] / m };
	m2 = m2 > 1 ? m2 : 1;
	m = m > 1 ? m : 1;
	double cosA = dir[0] * d[0] + dir[1] * d[1] + dir[2] * d[2];
	double cx = dir[1] * d[2] - dir[2] * d[1], cy = dir[2] * d[0] - dir[0] * d[2],
	       cz = dir[0] * d[1] - dir[1] * d[0];
	double sinA = sqrt(cx * cx + cy * cy + cz * cz), cosB = 1 / m, sinB = sqrt(m2 - 1) * cosB;
	return 1 / (cosA * cosB - sinA * sinB);
}

void cesium_quantized_mesh(const struct planet *p, const struct tile *t, const struct tile *nt,
			   unsigned char **out, size_t *n)
{
	const uint32_t T = t->size, S = T < 64 ? T : 64, V = (S + 1) * (S + 1);
	const double step = (double)T / S;
	const float *h = tile_f32(t);
	struct geo_rect r;
	grid_tile_rect(&t->key, &r);
	/* vertex (i, k): i west→east, k south→north (row S - k of the tile's corners) */
	double *hv = xmalloc(V * sizeof *hv);
	double hmin = INFINITY, hmax = -INFINITY;
	for (uint32_t k = 0; k <= S; k++)
		for (uint32_t i = 0; i <= S; i++) {
			double v = corner_height(h, T, i * step, (S - k) * step);
			hv[k * (S + 1) + i] = v;
			hmin = v < hmin ? v : hmin;
			hmax = v > hmax ? v : hmax;
		}
	/* Triangles, counter-clockwise seen from above; vertices renumbered by first use. */
	uint32_t ntri = 2 * S * S;
	uint32_t *tri = xmalloc((size_t)ntri * 3 * sizeof *tri);
	uint32_t *num = xmalloc(V * sizeof *num), *order = xmalloc(V * sizeof *order), next = 0;
	memset(num, 0xff, V * sizeof *num);
	size_t q = 0;
	for (uint32_t k = 0; k < S; k++)
		for (uint32_t i = 0; i < S; i++) {
			uint32_t v00 = k * (S + 1) + i, v10 = v00 + 1, v01 = v00 + S + 1,
				 v11 = v01 + 1;
			const uint32_t c[6] = { v00, v10, v11, v00, v11, v01 };
			for (int j = 0; j < 6; j++) {
				if (num[c[j]] == UINT32_MAX) {
					num[c[j]] = next;
					order[next++] = c[j];
				}
				tri[q++] = num[c[j]];
			}
		}
	/* header */
	double a = p->a, f = p->f;
	double clat = (r.north + r.south) / 2, clon = (r.west + r.east) / 2, C[3];
	ecef(a, f, clat, clon, (hmin + hmax) / 2, C);
	double radius = 0, maxmag = 0, b = a * (1 - f), d[3], dn;
	double cs[3] = { C[0] / a, C[1] / a, C[2] / b };
	dn = sqrt(cs[0] * cs[0] + cs[1] * cs[1] + cs[2] * cs[2]);
	for (int j = 0; j < 3; j++)
		d[j] = cs[j] / dn;
	bool occludable = true;
	for (uint32_t k = 0; k <= S; k++)
		for (uint32_t i = 0; i <= S; i++) {
			double lat = r.north - (r.north - r.south) * (double)(S - k) / S;
			double lon = r.west + (r.east - r.west) * (double)i / S, P[3];
			ecef(a, f, lat, lon, hv[k * (S + 1) + i], P);
			double dx = P[0] - C[0], dy = P[1] - C[1], dz = P[2] - C[2];
			double dist = sqrt(dx * dx + dy * dy + dz * dz);
			radius = dist > radius ? dist : radius;
			double ps[3] = { P[0] / a, P[1] / a, P[2] / b };
			double m = occlusion_magnitude(ps, d);
			if (!(m > 0) || !isfinite(m))
				occludable = false; /* a tile wider than the horizon */
			else if (m > maxmag)
				maxmag = m;
		}
	/* A tile no point can hide (levels 0 and 1): an occlusion point far out along its
	 * centre, visible from wherever the tile is. */
	if (!occludable)
		maxmag = 1e3;
	struct out o = { 0 };
	put_f64(&o, C[0]);
	put_f64(&o, C[1]);
	put_f64(&o, C[2]);
	put_f32(&o, (float)hmin);
	put_f32(&o, (float)hmax);
	put_f64(&o, C[0]);
	put_f64(&o, C[1]);
	put_f64(&o, C[2]);
	put_f64(&o, radius);
	put_f64(&o, d[0] * maxmag);
	put_f64(&o, d[1] * maxmag);
	put_f64(&o, d[2] * maxmag);
	/* vertices, in first-use order */
	put_u32(&o, V);
	const double span = hmax > hmin ? hmax - hmin : 1;
	for (int pass = 0; pass < 3; pass++) {
		int prev = 0;
		for (uint32_t j = 0; j < V; j++) {
			uint32_t v = order[j], i = v % (S + 1), k = v / (S + 1);
			int val = pass == 0   ? (int)lround(i * 32767.0 / S)
				  : pass == 1 ? (int)lround(k * 32767.0 / S)
					      : (int)lround((hv[v] - hmin) / span * 32767.0);
			put_u16(&o, zigzag(val - prev));
			prev = val;
		}
	}
	/* triangles: 16-bit indices (V ≤ 65² ≪ 65536); the data so far is 92 + 6V bytes: even */
	put_u32(&o, ntri);
	uint32_t highest = 0;
	for (size_t j = 0; j < (size_t)ntri * 3; j++) {
		put_u16(&o, (uint16_t)(highest - tri[j]));
		if (tri[j] == highest)
			highest++;
	}
	/* edges: west (i = 0), south (k = 0), east (i = S), north (k = S) */
	for (int e = 0; e < 4; e++) {
		put_u32(&o, S + 1);
		for (uint32_t s = 0; s <= S; s++) {
			uint32_t i = e == 0 ? 0 : e == 2 ? S : s, k = e == 1 ? 0 : e == 3 ? S : s;
			put_u16(&o, (uint16_t)num[k * (S + 1) + i]);
		}
	}
	/* octvertexnormals: east-north-up at the vertex's geodetic place → Earth-centred */
	if (nt && nt->type == PIX_NORMAL && nt->size == T) {
		put(&o, &(uint8_t){ 1 }, 1);
		put_u32(&o, 2 * V);
		for (uint32_t j = 0; j < V; j++) {
			uint32_t v = order[j], i = v % (S + 1), k = v / (S + 1);
			double enu[3];
			corner_normal(nt->data, T, i * step, (S - k) * step, enu);
			double lat = (r.north - (r.north - r.south) * (double)(S - k) / S) * M_PI / 180;
			double lon = (r.west + (r.east - r.west) * (double)i / S) * M_PI / 180;
			double sl = sin(lat), cl = cos(lat), so = sin(lon), co = cos(lon);
			double w[3] = { -so * enu[0] - sl * co * enu[1] + cl * co * enu[2],
					co * enu[0] - sl * so * enu[1] + cl * so * enu[2],
					cl * enu[1] + sl * enu[2] };
			uint8_t b2[2];
			oct_encode(w, b2);
			put(&o, b2, 2);
		}
	}
	free(hv);
	free(tri);
	free(num);
	free(order);
	*out = o.b;
	*n = o.n;
}
