#version 330 core
// Terrain shading: colour and normal clipmaps, lit by a sun in the east-north-up frame at the
// camera, hazed by the air the vertex shader integrated. Compiled in variants (view.c prepends
// the #defines; the defaults below are the full one): GEO_FRAG recomputes (lon, lat) per
// fragment from the interpolated direction — needed where a ring reaches the pole, so nothing is
// interpolated across the meridian behind it; elsewhere the vertices' (lon, lat) interpolate.
// BLEND samples the coarser level too, HAZE applies the vertex shader's air, EXAG steepens the
// normals by the vertical exaggeration, COLOR and NORMAL say which layers exist, SEA draws
// water where the vertex shader lifted the ground to sea level (ice where the colour layer
// shows it there). UNLIT writes the colour layer
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
#if SEA
in vec3 v_eye;
in float v_sea;         // the sea's surface (m, exaggerated): sea level, or on a geoid
uniform sampler2DArray u_height;
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
