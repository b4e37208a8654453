/* view_levels — the viewer's CPU-side geometry and level math (pure functions, no GL): level
 * visibility (seed 000 eq. 6 and 8), the detail levels worth texturing with, whether a level's
 * texture window covers its ring, the per-level shader parameters, and the camera (view and
 * projection matrices, CPU projection of a ground point for tests). The level plan itself
 * (ring radii, windows, lx per latitude, detail levels) is common/clipmap.h, shared with the
 * daemon's prefetch. Angles in radians unless named _deg. Thread-safe (no state).
 */
#ifndef CLIPMAP_VIEW_LEVELS_H
#define CLIPMAP_VIEW_LEVELS_H
#include <stdbool.h>
#include <stdint.h>

#include "common/clipmap.h"
#include "common/grid.h"

#define VIEW_MAX_LEVELS (GRID_MAX_LEVEL + 1)

struct view_body {
	double a, f, e2;
	double hmin, hmax; /* terrain height bounds assumed for horizon culling, metres */
};

void view_body_init(struct view_body *b, double a, double f);
/* Prime vertical radius of curvature N at geodetic latitude with sine s. */
double view_body_n(const struct view_body *b, double s);

/* The farthest view-space angle that can be visible from height alt above the ellipsoid
 * (eq. 6, widened by the terrain's height range). */
double view_horizon_cap(const struct view_body *b, double alt);

struct view_camera {
	double lat, lon; /* degrees, geodetic */
	double alt;	 /* metres above the ellipsoid */
	double heading, pitch; /* degrees: heading clockwise from north, pitch up from level */
	double fov_y;	 /* degrees; 0: 60 */
	int width, height;
};

/* Levels worth drawing: lmin = the coarsest ring not wholly beyond the horizon, lmax = the
 * finest whose triangles (n steps around) still cover about a pixel (eq. 7, 8).
 * agl = the camera's height above the ground. max_level: the planet's finest ly. */
void view_level_range(const struct view_body *b, const struct view_camera *c, double agl,
		      int n_phi, int max_level, int *lmin, int *lmax);
/* The finest level worth texturing with: lmax + CLIPMAP_DETAIL, no finer than a texel of about
 * half the pixel under the camera (finer texels would only alias), nor than max_level.
 * T: the tile size. */
int view_detail_max(const struct view_body *b, const struct view_camera *c, double agl,
		    uint32_t T, int lmax, int max_level);

/* Whether quad q's window holds every point within angle r of (lon, lat) with `margin`
 * texels to spare (the window's pole edges need no margin). */
bool view_window_covers(const struct grid_quad *q, double lon_deg, double lat_deg, double r,
			double margin);

/* Shader parameters of a level whose texture holds window q, for a camera at (lon, lat):
 * p[0], p[1]: the focus in toroidal-texture texels (may exceed S; GL_REPEAT wraps),
 * p[2], p[3]: texels per radian of longitude and of latitude (v grows south),
 * p[4], p[5]: the range texture v is clamped to (half a texel inside the poles). */
void view_level_params(const struct grid_quad *q, double lon_deg, double lat_deg, double p[6]);

/* Column-major 4×4 view-projection from the camera's local east-north-up frame (origin at the
 * camera) to clip space. reversed: depth 1 at the near plane → 0 at infinity (for
 * glClipControl zero-to-one with a float depth buffer); else a finite near/far in [-1, 1]. */
void view_camera_matrix(const struct view_camera *c, bool reversed, double near, double far,
			float out[16]);
/* Where ENU offset e (metres from the camera) lands on screen: pixel x, y (y down from the
 * top row) and whether it is in front of the camera. */
bool view_camera_project(const struct view_camera *c, const double e[3], double *px, double *py);
/* The ray through pixel centre (px, py) in ENU, unit length. */
void view_camera_ray(const struct view_camera *c, double px, double py, double dir[3]);
/* Where terrain.vert places the ring point at view-space angles (θ̃, φ̃) with (exaggerated)
 * height h, for a camera at geodetic latitude lat_deg, alt above the ellipsoid: ENU metres
 * from the camera, in doubles. */
void view_ring_point(const struct view_body *b, double lat_deg, double alt, double th, double ph,
		     double h, double out[3]);
/* Frustum culling of ring geometry: whether terrain of the sector θ̃ ∈ [th0, th1],
 * φ̃ ∈ [ph0, ph1] (heights within b->hmin..hmax; θ̃ beyond cap is drawn at cap) can show in
 * camera c's image (c->alt: above the ellipsoid; c->width, c->height set). Conservative:
 * false only when the whole sector lies outside one side plane of the frustum, behind the
 * camera, or beyond the cap (where its triangles collapse onto the cap circle). */
bool view_sector_visible(const struct view_body *b, const struct view_camera *c, double th0,
			 double th1, double ph0, double ph1, double cap);
/* (Δlon, Δlat) from the camera's nadir of the view-space direction (θ̃, φ̃), as terrain.vert
 * maps it (radians; the camera's geodetic latitude taken as spherical). */
void view_geo_delta(double lat_deg, double th, double ph, double *dlon, double *dlat);
/* The point an arc of `arc` radians from (lat, lon) along bearing `bearing` (radians from
 * north, east positive) reaches on a sphere: its latitude and its longitude (degrees; the
 * longitude not wrapped). Across a pole too. */
void view_sphere_direct(double lat_deg, double lon_deg, double bearing, double arc,
			double *lat2_deg, double *lon2_deg);
/* Bounds of the elevation angle (radians, above the camera's horizontal plane) at which
 * camera c (c->alt: above the ellipsoid) sees the ring points of the sector θ̃ ∈ [th0, th1],
 * φ̃ ∈ [ph0, ph1]: the least for heights ≥ h, the greatest for heights ≤ h, with a margin
 * for the samples between. For horizon culling: every line of sight in the sector's
 * directions meets ground no lower than the least, none of the sector rises above the
 * greatest. */
double view_sector_elev_min(const struct view_body *b, const struct view_camera *c, double th0,
			    double th1, double ph0, double ph1, double h);
double view_sector_elev_max(const struct view_body *b, const struct view_camera *c, double th0,
			    double th1, double ph0, double ph1, double h);
/* ECEF → the camera's ENU frame (rotation only). */
void view_ecef_to_enu(double lat_deg, double lon_deg, const double v[3], double out[3]);

#endif
