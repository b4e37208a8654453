#version 330 core
// Terrain shading: colour and normal clipmaps, lit by a sun in the east-north-up frame at the
// camera, hazed by the air the vertex shader integrated. Compiled in variants (view.c prepends
// the #defines; the defaults below are the full one): GEO_FRAG recomputes (lon, lat) per
// fragment from the interpolated direction — needed where a ring reaches the pole, so nothing is
// interpolated across the meridian behind it; elsewhere the vertices' (lon, lat) interpolate.
// BLEND samples the coarser level too, HAZE applies the vertex shader's air, EXAG steepens the
// normals by the vertical exaggeration, COLOR and NORMAL say which layers exist, SEA draws
// water where the vertex shader lifted the ground to sea level (ice where the colour layer
// shows it there). DERIVE (instead of NORMAL) makes the normals here from the height clipmap,
// as the `normal` node would (a viewer that does not fetch them). UNLIT writes the colour layer
// as it is (no light, air or water: what the textures put on screen, for measuring).

#ifndef BLEND
#define BLEND 1
#endif
#ifndef GEO_FRAG
#define GEO_FRAG 1
#endif
#ifndef HAZE
#define HAZE 1
#endif
#ifndef EXAG
#define EXAG 1
#endif
#ifndef COLOR
#define COLOR 1
#endif
#ifndef NORMAL
#define NORMAL 1
#endif
#ifndef SEA
#define SEA 1
#endif
#ifndef DERIVE
#define DERIVE 0
#endif
#ifndef UNLIT
#define UNLIT 0
#endif

in vec3 v_delta;
in vec2 v_g;
#if BLEND
in float v_blend;
#endif
#if HAZE
in vec3 v_tr;
in vec3 v_in;
#endif
#if SEA || DERIVE
uniform sampler2DArray u_height;
#endif
#if DERIVE && GEO_FRAG
uniform vec4 u_body;    // (as the vertex shader's) .w: e²
uniform float u_a;      // equatorial radius
#endif
#if DERIVE && !GEO_FRAG
in vec2 v_met;          // M(φ), N(φ)·cos φ: metres per radian north and east (vertex shader)
#endif
#if SEA
in vec3 v_eye;
in float v_sea;         // the sea's surface (m, exaggerated): sea level, or on a geoid
uniform float u_seamask; // 1: the colour's alpha says where the sea may lie (254 of 255: dry)
uniform vec2 u_sea;     // sea level (m, exaggerated), 1 / exaggeration
#endif
#if !GEO_FRAG
in vec3 v_sunl; // the sun in the point's east-north-up frame (the vertex shader's)
#endif

uniform vec3 u_lat;
uniform float u_T;
uniform vec4 u_df;      // the detail level of the level drawn (its colour and normals)
uniform vec2 u_dvf;
uniform float u_dsf;
uniform vec4 u_dc;      // the detail level of the coarser level it blends towards
uniform vec2 u_dvc;
uniform float u_dsc;
uniform vec3 u_sun;      // towards the sun, ENU at the camera
uniform float u_exag;    // vertical exaggeration: steepens the normals too
uniform sampler2DArray u_color;
uniform sampler2DArray u_normal;

out vec4 o_color;

#if GEO_FRAG
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
#endif

// The colour clipmap holds sRGB bytes in a plain RGBA8 texture: llvmpipe filters 8-bit unorm
// textures on a fast fixed-point path and sRGB ones in float, decoding all four texels of
// every lookup. Decoded here once, after filtering, as gamma 2 — and encoded back with a
// square root at the end: pow() costs llvmpipe an exp2 and a log2 per channel, which made the
// 2.2 curve a third of a 10 km frame's shading.
vec3 srgb_to_linear(vec3 c)
{
	return c * c;
}

vec4 tex4_at(sampler2DArray s, vec2 g, vec4 p, vec2 vc, float slice)
{
	float u = p.x + g.x * p.z;
	float v = clamp(p.y - g.y * p.w, vc.x, vc.y);
	return texture(s, vec3(u / u_T, v / u_T, slice));
}

vec3 tex_at(sampler2DArray s, vec2 g, vec4 p, vec2 vc, float slice)
{
	return tex4_at(s, g, p, vc, slice).rgb;
}

#if DERIVE
// The slopes (east, north) of the level at texel position (u, v) from its heights: central
// differences with metric texel spacing on the ellipsoid (east N(φ)·cos φ·Δλ, north M(φ)·Δφ),
// the `normal` node's arithmetic (node_normal.c) — including its wider east stencil next to a
// pole, where texels are far narrower east–west than tall (k texels, the chord of the
// parallel; at most 8 here: the window holds little more). Bilinear samples at ±1 texel give
// the bilinear blend of the texel-centre differences, as a fetched normal map would.
vec2 slopes_at(vec2 g, vec4 p, vec2 vc, float slice)
{
	float u = p.x + g.x * p.z;
	float v = clamp(p.y - g.y * p.w, vc.x, vc.y);
#if GEO_FRAG
	// near a pole: per fragment (the vertices' values would interpolate across it)
	float lat = u_lat.z + g.y;
	float sl = sin(lat);
	float w = 1.0 - u_body.w * sl * sl;
	float rn = u_a * inversesqrt(w);
	vec2 met = vec2(u_a * (1.0 - u_body.w) / (w * sqrt(w)), rn * max(cos(lat), 0.0));
#else
	vec2 met = v_met;
#endif
	float dy = met.x / p.w, dx = met.y / p.z;
	float k = dy >= 8.0 * dx ? min(floor(dy / (4.0 * dx)), 8.0) : 1.0;
	float len = k == 1.0 ? 2.0 * dx : 2.0 * met.y * sin(k / p.z);
	float he = texture(u_height, vec3((u + k) / u_T, v / u_T, slice)).r;
	float hw = texture(u_height, vec3((u - k) / u_T, v / u_T, slice)).r;
	float hn = texture(u_height, vec3(u / u_T, max(v - 1.0, vc.x) / u_T, slice)).r;
	float hs = texture(u_height, vec3(u / u_T, min(v + 1.0, vc.y) / u_T, slice)).r;
	// at the pole itself east is undefined (len → 0): no east slope there
	vec2 gr = vec2(len > 1e-3 * dy ? (he - hw) / len : 0.0, (hn - hs) / (2.0 * dy));
	return vec2(gr.x == gr.x ? gr.x : 0.0, gr.y == gr.y ? gr.y : 0.0);
}
#endif

void main()
{
#if GEO_FRAG
	vec2 g = geo_delta(v_delta);
#else
	vec2 g = v_g;
#endif
	float open = 1.0; // the sea may lie here (the colour's alpha with a sea mask)
#if COLOR
	vec4 c4 = tex4_at(u_color, g, u_df, u_dvf, u_dsf);
#if BLEND
	c4 = mix(c4, tex4_at(u_color, g, u_dc, u_dvc, u_dsc), v_blend);
#endif
	vec3 albedo = c4.rgb;
#if SEA
	open = u_seamask > 0.5 ? step(254.5 / 255.0, c4.a) : 1.0;
#endif
#if UNLIT
	o_color = vec4(albedo, 1.0);
	return;
#endif
#if SEA
	// Ice on the sea: where the colour layer shows near-white (sea ice, ice shelves: bright,
	// unsaturated), the surface is drawn as that ice, not as water.
	float lum = dot(albedo, vec3(0.30, 0.59, 0.11));
	float sat = max(albedo.r, max(albedo.g, albedo.b)) - min(albedo.r, min(albedo.g, albedo.b));
	float ice = smoothstep(0.70, 0.82, lum) * (1.0 - smoothstep(0.10, 0.22, sat));
#endif
	albedo = srgb_to_linear(albedo);
#else
	vec3 albedo = vec3(0.5);
#if SEA
	float ice = 0.0;
#endif
#endif
#if NORMAL
	vec2 en = tex_at(u_normal, g, u_df, u_dvf, u_dsf).rg;
#if BLEND
	en = mix(en, tex_at(u_normal, g, u_dc, u_dvc, u_dsc).rg, v_blend);
#endif
	en = en * (255.0 / 127.5) - 1.0;
#elif DERIVE
	vec2 gr = slopes_at(g, u_df, u_dvf, u_dsf);
#if BLEND
	if (v_blend > 0.0) // most of a ring is not blended: 4 samples, not 8
		gr = mix(gr, slopes_at(g, u_dc, u_dvc, u_dsc), v_blend);
#endif
	vec2 en = -gr * inversesqrt(1.0 + dot(gr, gr));
#else
	vec2 en = vec2(0.0);
#endif
	float up = sqrt(max(0.0, 1.0 - dot(en, en)));
#if EXAG
	vec3 sn = normalize(vec3(en * u_exag, up)); // slopes × exaggeration
	en = sn.xy;
	up = sn.z;
#endif

	// Lighting in the point's own east-north-up frame: its up is (0, 0, 1), the normal
	// (en, up). The sun and the eye in that frame come from the vertex shader, or near a pole
	// (GEO_FRAG), where that frame turns fast, are built here.
#if GEO_FRAG
	vec3 U = normalize(v_delta + vec3(0.0, 0.0, 1.0));
	vec3 E = cross(vec3(0.0, u_lat.y, u_lat.x), U);
	E *= inversesqrt(max(dot(E, E), 1e-12));
	vec3 Nn = cross(U, E);
	vec3 sunl = vec3(dot(u_sun, E), dot(u_sun, Nn), dot(u_sun, U));
#if SEA
	vec3 eyel = vec3(dot(v_eye, E), dot(v_eye, Nn), dot(v_eye, U));
#endif
#else
	vec3 sunl = v_sunl;
#if SEA
	vec3 eyel = v_eye;
#endif
#endif
	vec3 nrm = vec3(en, up);
	float day = smoothstep(-0.1, 0.1, sunl.z);
#if SEA
	// Water: flat, the floor's colour fading into deep-water blue with depth (the first few
	// metres show the floor, a hundred hide it), and the sun's glint on top. The depth is
	// the sea level less the heights of the levels the colour comes from, per fragment: the
	// coast follows those texels, not the rings' vertices (which the vertex shader lifts to
	// the water's surface).
	float hd = tex_at(u_height, g, u_df, u_dvf, u_dsf).r;
#if BLEND
	hd = mix(hd, tex_at(u_height, g, u_dc, u_dvc, u_dsc).r, v_blend);
#endif
	float depth = v_sea * u_sea.y - hd;
	float below = step(0.0, depth) * open; // at the sea's surface: water, or ice on it
	float wet = below * (1.0 - ice);
	float clear = exp2(max(depth, 0.0) * (-1.4427 / 30.0)); // e^(-depth / 30 m)
	albedo = mix(albedo, mix(vec3(0.004, 0.02, 0.05), albedo * vec3(0.35, 0.6, 0.7), clear),
		     wet);
	nrm = mix(nrm, vec3(0.0, 0.0, 1.0), below); // below is 0 or 1: flat water, flat ice
#endif
	float diff = max(dot(nrm, sunl), 0.0);
	float sky = 0.5 + 0.5 * nrm.z; // the open sky a slope sees
	vec3 lit = albedo * (vec3(1.0, 0.97, 0.92) * 1.05 * diff * day +
			     vec3(0.30, 0.38, 0.50) * 0.22 * sky * (0.1 + 0.9 * day) + 0.015);
#if SEA
	// The glint: Phong around the sun's mirror image, cos^375 as e^(-375 (1 - cos)) (one
	// exp2; pow() costs llvmpipe a log2 too), brighter towards grazing (Schlick's Fresnel).
	vec3 eye = eyel * inversesqrt(dot(eyel, eyel));
	float c = max(eye.z, 0.0);
	float spec = exp2((dot(vec3(0.0, 0.0, 2.0 * c) - eye, sunl) - 1.0) * (375.0 * 1.4427));
	float m = 1.0 - c, m2 = m * m;
	float fres = 0.02 + 0.98 * m2 * m2 * m;
	lit += wet * day * (vec3(1.0, 0.95, 0.85) * 6.0 * spec * (0.2 + fres) +
			    vec3(0.30, 0.38, 0.50) * 0.25 * fres);
#endif
#if HAZE
	lit = lit * v_tr + v_in;
#endif
	o_color = vec4(sqrt(clamp(lit, 0.0, 1.0)), 1.0);
}
