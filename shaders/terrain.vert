#version 330 core
// Spherical clipmap terrain (seed 000): static rings around the point under the camera,
// mapped to (lon, lat) by the camera's latitude, displaced by the height clipmap, placed
// relative to the camera in its east-north-up frame. All large quantities (radii, camera
// height) enter as differences that float holds exactly enough at 1 m above an Earth-size body.
// Compiled in variants (view.c prepends the #defines; the defaults below are the full one):
// BLEND samples the coarser level too (the outer part of a ring, or a level fading in), HAZE
// computes the air's transmittance and in-scatter here, per vertex, SEA lifts the ground below
// sea level to the water's surface (the fragment shader finds the depth from the heights).

#ifndef BLEND
#define BLEND 1
#endif
#ifndef HAZE
#define HAZE 1
#endif
#ifndef SEA
#define SEA 1
#endif
#ifndef GEO_FRAG
#define GEO_FRAG 1
#endif

layout(location = 0) in vec3 a_ring; // sin φ̃, cos φ̃ (φ̃ = 0: north), θ̃ (angle from the nadir)

uniform mat4 u_vp;      // ENU (camera at the origin) → clip
uniform vec3 u_lat;     // sin, cos of the camera's geodetic latitude, the latitude (rad)
uniform vec4 u_body;    // N(camera) + h(camera), h(camera), N(camera), e²
uniform float u_a;      // equatorial radius
uniform float u_cap;    // θ̃ beyond which nothing can be seen
uniform vec3 u_blend;   // outer θ̃ of the level being drawn, blend start and end (× it)
uniform float u_T;      // clipmap texture size
uniform vec4 u_pf;      // fine level: focus texel u, v, texels per radian lon, lat
uniform vec2 u_vf;      // fine level: v clamp
uniform float u_sf;     // fine level: array slice
uniform vec4 u_pc;      // coarse level (blended in towards the outer edge)
uniform vec2 u_vc;
uniform float u_sc;
uniform float u_fade;   // 1: the fine level fully shown; < 1 while it fades in
uniform float u_exag;   // vertical exaggeration of the relief (1: true scale)
uniform vec3 u_sun;     // towards the sun, ENU at the camera
uniform vec4 u_haze;    // scale height (m, exaggerated), extinction per m of sea-level air (rgb)
uniform vec2 u_sea;     // sea level (m, exaggerated), 1 / exaggeration
uniform sampler2DArray u_height;
#if SEA
uniform sampler2D u_seag; // the sea's surface above sea level (m): a lat/lon lattice, rows from
			  // the south pole to the north, columns from −180° east (seagrid.h)
uniform vec3 u_seagrid;   // its rows and columns; the camera's longitude (rad)
uniform float u_seamask;  // 1: the colour's alpha says where the sea may lie (254 of 255: dry)
uniform sampler2DArray u_color;
uniform vec4 u_df;        // the levels the colour comes from (as in the fragment shader)
uniform vec2 u_dvf;
uniform float u_dsf;
uniform vec4 u_dc;
uniform vec2 u_dvc;
uniform float u_dsc;
#endif

out vec3 v_delta; // unit normal minus the camera's up, ENU: the fragment's up, (lon, lat)
out vec2 v_g;     // (Δlon, Δlat) from the camera's nadir
#if BLEND
out float v_blend;
#endif
#if HAZE
out vec3 v_tr;    // transmittance of the air between the camera and the point
out vec3 v_in;    // light scattered into the ray by that air
#endif
#if SEA
out vec3 v_eye;    // from the point to the camera: ENU, or the point's ENU without GEO_FRAG
out float v_sea;   // the sea's surface here (m, exaggerated)
#endif
#if !GEO_FRAG
out vec3 v_sunl;   // towards the sun in the point's east-north-up frame
#endif

// (Δlon, Δlat) of the direction up + d from the camera's nadir, without cancellation.
vec2 geo_delta(vec3 d)
{
	float sl = u_lat.x, cl = u_lat.y;
	float dx = cl * (1.0 + d.z) - sl * d.y;
	float dy = d.x;
	float dz = sl * (1.0 + d.z) + cl * d.y;
	float rho = sqrt(dx * dx + dy * dy);
	float cr = dx > 0.0 ? d.y - sl * dy * dy / (rho + dx) : cl * dz - sl * rho;
	float dt = cl * rho + sl * dz;
	return vec2(atan(dy, dx), atan(cr, dt));
}

float height_at(vec2 g, vec4 p, vec2 vc, float slice)
{
	float u = p.x + g.x * p.z;
	float v = clamp(p.y - g.y * p.w, vc.x, vc.y);
	return textureLod(u_height, vec3(u / u_T, v / u_T, slice), 0.0).r;
}

#if SEA
// The sea's surface at (Δlon, Δlat) from the camera's nadir: sea level plus the lattice there.
float sea_at(vec2 g)
{
	const float PI = 3.14159265;
	float lon = u_seagrid.z + g.x, lat = u_lat.z + g.y;
	vec2 st = vec2((lon + PI) / (2.0 * PI) + 0.5 / u_seagrid.y,
		       ((lat + 0.5 * PI) / PI * (u_seagrid.x - 1.0) + 0.5) / u_seagrid.x);
	return u_sea.x + textureLod(u_seag, st, 0.0).r * u_exag;
}

// The colour's alpha at (Δlon, Δlat) on a colour level (its focus, v clamp and slice).
float alpha_at(vec2 g, vec4 p, vec2 vc, float slice)
{
	float u = p.x + g.x * p.z;
	float v = clamp(p.y - g.y * p.w, vc.x, vc.y);
	return textureLod(u_color, vec3(u / u_T, v / u_T, slice), 0.0).a;
}
#endif

void main()
{
	float th = min(a_ring.z, u_cap);
	float st = sin(th), sh = sin(0.5 * th);
	vec3 d = vec3(st * a_ring.x, st * a_ring.y, -2.0 * sh * sh);
	vec2 g = geo_delta(d);
	float hf = height_at(g, u_pf, u_vf, u_sf);
#if BLEND
	float w = clamp((th / u_blend.x - u_blend.y) / (u_blend.z - u_blend.y), 0.0, 1.0);
	w = max(w, 1.0 - u_fade);
	float hc = height_at(g, u_pc, u_vc, u_sc);
	float h = mix(hf, hc, w) * u_exag;
	v_blend = w;
#else
	float h = hf * u_exag;
#endif
#if SEA
	v_sea = sea_at(g);
	bool open = true; // the sea may lie here (not a dry basin below sea level)
	if (u_seamask > 0.5) {
		float a = alpha_at(g, u_df, u_dvf, u_dsf);
#if BLEND
		a = mix(a, alpha_at(g, u_dc, u_dvc, u_dsc), w);
#endif
		open = a >= 254.5 / 255.0;
	}
	if (open)
		h = max(h, v_sea); // the fragment shader tells water from land per fragment
#endif

	// P - C = (Nc+hc)·d + (N-Nc + h-hc)·n - e²·(N·(s-sc) + (N-Nc)·sc)·ẑ
	float sl = u_lat.x, cl = u_lat.y, e2 = u_body.w;
	float ds = d.y * cl + d.z * sl; // s - sc
	float s = sl + ds;
	float A = sqrt(1.0 - e2 * s * s), B = sqrt(1.0 - e2 * sl * sl);
	float dN = u_a * e2 * ds * (s + sl) / (A * B * (A + B));
	float N = u_body.z + dN;
	vec3 n = vec3(d.x, d.y, 1.0 + d.z);
	vec3 zhat = vec3(0.0, cl, sl);
	vec3 pos = u_body.x * d + (dN + (h - u_body.y)) * n - e2 * (N * ds + dN * sl) * zhat;

	v_delta = d;
	v_g = g;
#if GEO_FRAG
#if SEA
	v_eye = -pos;
#endif
#else
	// the point's east, north (up is n): away from the poles, never degenerate
	vec3 E = normalize(cross(zhat, n));
	vec3 Nn = cross(n, E);
	v_sunl = vec3(dot(u_sun, E), dot(u_sun, Nn), dot(u_sun, n));
#if SEA
	v_eye = vec3(-dot(pos, E), -dot(pos, Nn), -dot(pos, n));
#endif
#endif
#if HAZE
	// Air between the camera and the point: an exponential atmosphere integrated along the
	// straight ray (exact for a flat one, a good fit for short rays and slant views).
	float H = u_haze.x;
	float sd = length(pos);
	float cz = dot(-pos, n) / max(sd, 1e-3); // cos of the ray's zenith angle at the point
	float x = sd * (cz > 0.0 ? max(cz, 0.025) : cz) / H;
	x = max(x, -30.0);
	float f = abs(x) < 1e-3 ? 1.0 - 0.5 * x : (1.0 - exp(-x)) / x;
	float air = sd * exp(-max(h, 0.0) / H) * f; // metres of sea-level air
	air /= 1.0 + (u_exag - 1.0) * cz * cz;      // exaggerated verticals hold no more air
	v_tr = exp(-u_haze.yzw * air);
	// Light scattered into the ray: single scattering of the sunlight that reaches the air
	// (less under a low sun, whose light crosses more air first), about a quarter of what a
	// white ground under the same sun would send back.
	float mu = dot(n, u_sun);
	float day = smoothstep(-0.1, 0.1, mu);
	v_in = (1.0 - v_tr) * vec3(1.0, 0.96, 0.90) * (0.03 + 0.97 * day) *
	       (0.12 + 0.23 * sqrt(max(mu, 0.0)));
#endif
	gl_Position = u_vp * vec4(pos, 1.0);
}
