/* view_levels — see view_levels.h. */
#include "view_levels.h"

#include <math.h>

#define DEG (M_PI / 180.0)
void view_body_init(struct view_body *b, double a, double f)
{
	b->a = a;
	b->f = f;
	b->e2 = f * (2 - f);
	b->hmin = -11000;
	b->hmax = 9000;
}

double view_body_n(const struct view_body *b, double s) { return b->a / sqrt(1 - b->e2 * s * s); }

double view_horizon_cap(const struct view_body *b, double alt)
{
	double r0 = b->a + b->hmin;
	double c1 = acos(fmin(1.0, r0 / (b->a + fmax(alt, b->hmin))));
	double c2 = acos(r0 / (b->a + b->hmax));
	return fmin(c1 + c2, clipmap_ring_radius(0));
}

void view_level_range(const struct view_body *b, const struct view_camera *c, double agl,
		      int n_phi, int max_level, int *lmin, int *lmax)
{
	double cap = view_horizon_cap(b, c->alt);
	int lo = 0;
	while (lo < max_level && clipmap_ring_radius(lo + 1) >= cap)
		lo++;
	double fov = (c->fov_y > 0 ? c->fov_y : 60) * DEG;
	double s = fmax(agl, 0.5) * tan(fov / (c->height > 0 ? c->height : 720));
	double need = s * n_phi / (2 * M_PI) / b->a;
	int hi = lo;
	while (hi < max_level && clipmap_ring_radius(hi + 1) >= need)
		hi++;
	*lmin = lo;
	*lmax = hi;
}

int view_detail_max(const struct view_body *b, const struct view_camera *c, double agl,
		    uint32_t T, int lmax, int max_level)
{
	double fov = (c->fov_y > 0 ? c->fov_y : 60) * DEG;
	double px = fmax(agl, 0.05) * 2 * tan(fov / 2) / (c->height > 0 ? c->height : 720);
	/* level L's texels are π·a / (T·2^L) metres tall: ≥ px / 2 */
	double lim = floor(log2(2 * M_PI * b->a / ((double)T * px)));
	int d = lmax + CLIPMAP_DETAIL;
	if (d > lim)
		d = (int)lim;
	if (d > max_level)
		d = max_level;
	return d < lmax ? lmax : d;
}

/* The focus's u relative to the window origin, in (-(W-w)/2, (W+w)/2]. */
static double focus_rel_u(const struct grid_quad *q, double lon_deg)
{
	return grid_window_rel_u(q, grid_lon_to_u(q->lx, q->T, lon_deg));
}

bool view_window_covers(const struct grid_quad *q, double lon_deg, double lat_deg, double r,
			double margin)
{
	double T = q->T, w = q->w, h = q->h;
	double H = (double)grid_tiles_y(q->ly) * T, W = (double)grid_tiles_x(q->lx) * T;
	double rd = r / DEG;
	double vlo = lat_deg + rd >= 90 ? 0 : grid_lat_to_v(q->ly, q->T, lat_deg + rd);
	double vhi = lat_deg - rd <= -90 ? H : grid_lat_to_v(q->ly, q->T, lat_deg - rd);
	double alo = q->v0 == 0 ? 0 : (double)q->v0 + margin;
	double ahi = (double)q->v0 + h >= H ? H : (double)q->v0 + h - margin;
	if (vlo < alo || vhi > ahi)
		return false;
	if (W <= w)
		return true;
	double ext = clipmap_lon_extent(lat_deg, r);
	if (ext >= M_PI)
		return false;
	double rel = focus_rel_u(q, lon_deg), du = ext * W / (2 * M_PI);
	return rel - du >= margin && rel + du <= w - margin;
}

void view_level_params(const struct grid_quad *q, double lon_deg, double lat_deg, double p[6])
{
	double T = q->T;
	double H = (double)grid_tiles_y(q->ly) * T, W = (double)grid_tiles_x(q->lx) * T;
	double u0m = (double)(q->u0 % q->S), v0m = (double)(q->v0 % q->S);
	p[0] = u0m + focus_rel_u(q, lon_deg);
	p[1] = v0m + (grid_lat_to_v(q->ly, q->T, lat_deg) - (double)q->v0);
	p[2] = W / (2 * M_PI);
	p[3] = H / M_PI;
	p[4] = v0m + 0.5 - (double)q->v0;
	p[5] = v0m + H - 0.5 - (double)q->v0;
}

/* The camera basis in ENU: right, up, forward. */
static void basis(const struct view_camera *c, double r[3], double u[3], double f[3])
{
	double h = c->heading * DEG, p = c->pitch * DEG;
	f[0] = sin(h) * cos(p);
	f[1] = cos(h) * cos(p);
	f[2] = sin(p);
	r[0] = cos(h);
	r[1] = -sin(h);
	r[2] = 0;
	u[0] = r[1] * f[2] - r[2] * f[1];
	u[1] = r[2] * f[0] - r[0] * f[2];
	u[2] = r[0] * f[1] - r[1] * f[0];
}

static void focal(const struct view_camera *c, double *fx, double *fy)
{
	double fov = (c->fov_y > 0 ? c->fov_y : 60) * DEG;
	*fy = 1 / tan(fov / 2);
	*fx = *fy * (double)c->height / (double)c->width;
}

void view_camera_matrix(const struct view_camera *c, bool reversed, double near, double far,
			float out[16])
{
	double r[3], u[3], f[3], fx, fy;
	basis(c, r, u, f);
	focal(c, &fx, &fy);
	/* view: rows r, u, -f; projection P; out = P · V, column-major. */
	double V[3][3] = { { r[0], r[1], r[2] }, { u[0], u[1], u[2] }, { -f[0], -f[1], -f[2] } };
	double pz, pw; /* clip z = pz · z_view + pw, clip w = -z_view */
	if (reversed) {
		pz = 0;
		pw = near;
	} else {
		pz = (far + near) / (near - far);
		pw = 2 * far * near / (near - far);
	}
	for (int col = 0; col < 3; col++) {
		out[col * 4 + 0] = (float)(fx * V[0][col]);
		out[col * 4 + 1] = (float)(fy * V[1][col]);
		out[col * 4 + 2] = (float)(pz * V[2][col]);
		out[col * 4 + 3] = (float)(-V[2][col]);
	}
	out[12] = 0;
	out[13] = 0;
	out[14] = (float)pw;
	out[15] = 0;
}

bool view_camera_project(const struct view_camera *c, const double e[3], double *px, double *py)
{
	double r[3], u[3], f[3], fx, fy;
	basis(c, r, u, f);
	focal(c, &fx, &fy);
	double x = r[0] * e[0] + r[1] * e[1] + r[2] * e[2];
	double y = u[0] * e[0] + u[1] * e[1] + u[2] * e[2];
	double z = f[0] * e[0] + f[1] * e[1] + f[2] * e[2];
	if (z <= 0)
		return false;
	*px = (fx * x / z + 1) / 2 * c->width;
	*py = (1 - fy * y / z) / 2 * c->height;
	return true;
}

void view_camera_ray(const struct view_camera *c, double px, double py, double dir[3])
{
	double r[3], u[3], f[3], fx, fy;
	basis(c, r, u, f);
	focal(c, &fx, &fy);
	double nx = 2 * px / c->width - 1, ny = 1 - 2 * py / c->height;
	double len = 0;
	for (int i = 0; i < 3; i++) {
		dir[i] = f[i] + r[i] * nx / fx + u[i] * ny / fy;
		len += dir[i] * dir[i];
	}
	len = sqrt(len);
	for (int i = 0; i < 3; i++)
		dir[i] /= len;
}

void view_ecef_to_enu(double lat_deg, double lon_deg, const double v[3], double out[3])
{
	double sp = sin(lat_deg * DEG), cp = cos(lat_deg * DEG);
	double sl = sin(lon_deg * DEG), cl = cos(lon_deg * DEG);
	out[0] = -sl * v[0] + cl * v[1];
	out[1] = -sp * cl * v[0] - sp * sl * v[1] + cp * v[2];
	out[2] = cp * cl * v[0] + cp * sl * v[1] + sp * v[2];
}

void view_ring_point(const struct view_body *b, double lat_deg, double alt, double th, double ph,
		     double h, double out[3])
{
	double sl = sin(lat_deg * DEG), cl = cos(lat_deg * DEG), e2 = b->e2;
	double Nc = view_body_n(b, sl);
	double st = sin(th), sh = sin(0.5 * th);
	double d[3] = { st * sin(ph), st * cos(ph), -2 * sh * sh };
	double ds = d[1] * cl + d[2] * sl, s = sl + ds;
	double A = sqrt(1 - e2 * s * s), B = sqrt(1 - e2 * sl * sl);
	double dN = b->a * e2 * ds * (s + sl) / (A * B * (A + B));
	double N = Nc + dN;
	double n[3] = { d[0], d[1], 1 + d[2] }, z[3] = { 0, cl, sl };
	double k = e2 * (N * ds + dN * sl);
	for (int i = 0; i < 3; i++)
		out[i] = (Nc + alt) * d[i] + (dN + h - alt) * n[i] - k * z[i];
}

/* Samples per sector: the surface patch between neighbouring samples (angle ≤ δ apart)
 * bulges at most ρ(1 − cos δ) beyond their convex hull. */
#define SEC_NTH 5
#define SEC_NPH 3

bool view_sector_visible(const struct view_body *b, const struct view_camera *c, double th0,
			 double th1, double ph0, double ph1, double cap)
{
	if (th0 >= cap)
		return false;
	th1 = fmin(th1, cap);
	double r[3], u[3], f[3], fx, fy;
	basis(c, r, u, f);
	focal(c, &fx, &fy);
	/* Outward normals of the four side planes and the plane behind the camera (all through
	 * the camera): a point p is outside plane k when pl[k]·p > 0. */
	double pl[5][3];
	for (int i = 0; i < 3; i++) {
		pl[0][i] = fx * r[i] - f[i];
		pl[1][i] = -fx * r[i] - f[i];
		pl[2][i] = fy * u[i] - f[i];
		pl[3][i] = -fy * u[i] - f[i];
		pl[4][i] = -f[i];
	}
	for (int k = 0; k < 5; k++) {
		double len = sqrt(pl[k][0] * pl[k][0] + pl[k][1] * pl[k][1] + pl[k][2] * pl[k][2]);
		for (int i = 0; i < 3; i++)
			pl[k][i] /= len;
	}
	double dth = (th1 - th0) / (SEC_NTH - 1), dph = (ph1 - ph0) / (SEC_NPH - 1);
	double delta = hypot(dth, sin(fmin(th1, M_PI / 2)) * dph);
	double rho = view_body_n(b, 1) + fmax(fabs(b->hmax), fabs(b->hmin));
	double dmin[5] = { INFINITY, INFINITY, INFINITY, INFINITY, INFINITY }, pmax = 0;
	for (int i = 0; i < SEC_NTH; i++)
		for (int j = 0; j < SEC_NPH; j++)
			for (int m = 0; m < 2; m++) {
				double p[3];
				view_ring_point(b, c->lat, c->alt, th0 + i * dth, ph0 + j * dph,
						m ? b->hmax : b->hmin, p);
				for (int k = 0; k < 5; k++)
					dmin[k] = fmin(dmin[k], pl[k][0] * p[0] + pl[k][1] * p[1] +
									pl[k][2] * p[2]);
				pmax = fmax(pmax, fabs(p[0]) + fabs(p[1]) + fabs(p[2]));
			}
	/* The bulge (twice the bound: the ellipsoid is not a sphere), float rounding in the
	 * shader, and a centimetre. */
	double margin = 2 * rho * (1 - cos(delta)) + 1e-5 * pmax + 0.01;
	for (int k = 0; k < 5; k++)
		if (dmin[k] > margin)
			return false;
	return true;
}

void view_sphere_direct(double lat_deg, double lon_deg, double bearing, double arc,
			double *lat2_deg, double *lon2_deg)
{
	const double rad = M_PI / 180.0;
	double p1 = lat_deg * rad;
	double sp2 = fmax(-1.0, fmin(1.0, sin(p1) * cos(arc) + cos(p1) * sin(arc) * cos(bearing)));
	*lat2_deg = asin(sp2) / rad;
	*lon2_deg = lon_deg +
		    atan2(sin(bearing) * sin(arc) * cos(p1), cos(arc) - sin(p1) * sp2) / rad;
}

void view_geo_delta(double lat_deg, double th, double ph, double *dlon, double *dlat)
{
	double sl = sin(lat_deg * DEG), cl = cos(lat_deg * DEG);
	double st = sin(th), sh = sin(0.5 * th);
	double d[3] = { st * sin(ph), st * cos(ph), -2 * sh * sh };
	double dx = cl * (1 + d[2]) - sl * d[1], dy = d[0], dz = sl * (1 + d[2]) + cl * d[1];
	double rho = sqrt(dx * dx + dy * dy);
	double cr = dx > 0 ? d[1] - sl * dy * dy / (rho + dx) : cl * dz - sl * rho;
	double dt = cl * rho + sl * dz;
	*dlon = atan2(dy, dx);
	*dlat = atan2(cr, dt);
}

static double elevation(const struct view_body *b, const struct view_camera *c, double th,
			double ph, double h)
{
	double p[3];
	view_ring_point(b, c->lat, c->alt, th, ph, h, p);
	return atan2(p[2], hypot(p[0], p[1]));
}

/* The margin for the points between the samples (φ̃: the ellipsoid's small part; θ̃: the
 * flat top of a peak), radians: about a fiftieth of a pixel at 720p; samples of φ̃ no more
 * than ELEV_DPH apart. */
#define ELEV_MARGIN 3e-4
#define ELEV_DPH (2.9 * M_PI / 180)

static int elev_nph(double ph0, double ph1) { return 1 + (int)ceil((ph1 - ph0) / ELEV_DPH); }

/* At a fixed height the elevation rises with θ̃ up to the line of sight's tangent point (for
 * ground below the camera) and falls after it: its least over [th0, th1] is at an end, its
 * greatest at an end or the tangent point. It rises with the height (up tilts towards the
 * camera for θ̃ < π). */
double view_sector_elev_min(const struct view_body *b, const struct view_camera *c, double th0,
			    double th1, double ph0, double ph1, double h)
{
	double e = INFINITY;
	int nph = elev_nph(ph0, ph1);
	for (int j = 0; j < nph; j++) {
		double ph = ph0 + (ph1 - ph0) * j / (nph - 1);
		e = fmin(e, fmin(elevation(b, c, th0, ph, h), elevation(b, c, th1, ph, h)));
	}
	return e - ELEV_MARGIN;
}

double view_sector_elev_max(const struct view_body *b, const struct view_camera *c, double th0,
			    double th1, double ph0, double ph1, double h)
{
	double n = view_body_n(b, sin(c->lat * DEG));
	double ct = (n + h) / (n + c->alt), ths[3] = { th0, th1, th0 };
	int nt = 2;
	if (ct < 1) {
		double tt = acos(ct);
		if (tt > th0 && tt < th1)
			ths[nt++] = tt;
	}
	double e = -INFINITY;
	int nph = elev_nph(ph0, ph1);
	for (int j = 0; j < nph; j++) {
		double ph = ph0 + (ph1 - ph0) * j / (nph - 1);
		for (int t = 0; t < nt; t++)
			e = fmax(e, elevation(b, c, ths[t], ph, h));
	}
	return e + ELEV_MARGIN;
}
