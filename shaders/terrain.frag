#version 330 core
// Terrain shading: colour and normal clipmaps sampled per fragment at the fragment's own
// (lon, lat) — recomputed from the interpolated direction, so nothing is interpolated across
// the meridian behind a pole — lit by a sun, hazed by distance.

in vec3 v_delta;
in vec3 v_pos;
in float v_blend;
in float v_h;

uniform vec3 u_lat;
uniform float u_T;
uniform vec4 u_pf;
uniform vec2 u_vf;
uniform float u_sf;
uniform vec4 u_pc;
uniform vec2 u_vc;
uniform float u_sc;
uniform vec3 u_sun;      // towards the sun, in the frame with the camera on meridian 0
uniform vec4 u_haze;     // scale height (m, exaggerated), strength (0: no air), unused ×2
uniform vec4 u_body;     // N + h, h of the camera (exaggerated), N, e²
uniform float u_exag;    // vertical exaggeration: steepens the normals too
uniform int u_layers;    // bit 0: colour present, bit 1: normals present
uniform sampler2DArray u_color;
uniform sampler2DArray u_normal;

out vec4 o_color;

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

vec3 tex_at(sampler2DArray s, vec2 g, vec4 p, vec2 vc, float slice)
{
	float u = p.x + g.x * p.z;
	float v = clamp(p.y - g.y * p.w, vc.x, vc.y);
	return texture(s, vec3(u / u_T, v / u_T, slice)).rgb;
}

void main()
{
	vec2 g = geo_delta(v_delta);
	float w = v_blend;
	vec3 albedo = vec3(0.5);
	if ((u_layers & 1) != 0)
		albedo = mix(tex_at(u_color, g, u_pf, u_vf, u_sf), tex_at(u_color, g, u_pc, u_vc, u_sc), w);
	vec2 en = vec2(0.0);
	if ((u_layers & 2) != 0) {
		vec2 nf = tex_at(u_normal, g, u_pf, u_vf, u_sf).rg;
		vec2 nc = tex_at(u_normal, g, u_pc, u_vc, u_sc).rg;
		en = mix(nf, nc, w) * (255.0 / 127.5) - 1.0;
	}
	float up = sqrt(max(0.0, 1.0 - dot(en, en)));
	if (u_exag != 1.0) { // slopes × exaggeration
		vec3 sn = normalize(vec3(en * u_exag, up));
		en = sn.xy;
		up = sn.z;
	}

	// The fragment's local frame in the frame where the camera sits on meridian 0.
	float lat = u_lat.z + g.y, lon = g.x;
	float sp = sin(lat), cp = cos(lat), so = sin(lon), co = cos(lon);
	vec3 E = vec3(-so, co, 0.0);
	vec3 Nn = vec3(-sp * co, -sp * so, cp);
	vec3 U = vec3(cp * co, cp * so, sp);
	vec3 nrm = normalize(en.x * E + en.y * Nn + up * U);
	float diff = max(dot(nrm, u_sun), 0.0);
	float day = smoothstep(-0.1, 0.1, dot(U, u_sun));
	float sky = 0.5 + 0.5 * dot(nrm, U); // the open sky a slope sees
	vec3 lit = albedo * (vec3(1.0, 0.97, 0.92) * 1.05 * diff * day +
			     vec3(0.30, 0.38, 0.50) * 0.22 * sky * (0.1 + 0.9 * day) + 0.015);

	if (u_haze.y > 0.0) {
		float H = u_haze.x;
		float s = length(v_pos);
		vec3 upp = normalize(v_delta + vec3(0.0, 0.0, 1.0));
		float cz = dot(-v_pos, upp) / max(s, 1e-3); // cos of the ray's zenith angle there
		float x = s * (cz > 0.0 ? max(cz, 0.025) : cz) / H;
		x = max(x, -30.0);
		float f = abs(x) < 1e-3 ? 1.0 - 0.5 * x : (1.0 - exp(-x)) / x;
		float air = s * exp(-max(v_h, 0.0) / H) * f; // metres of sea-level air
		air /= 1.0 + (u_exag - 1.0) * cz * cz; // exaggerated verticals hold no more air
		vec3 beta = (vec3(5.8e-6, 13.5e-6, 33.1e-6) + 2.0e-6) * (0.45 * u_haze.y);
		vec3 tr = exp(-beta * air);
		vec3 sunlight = vec3(1.0, 0.96, 0.90) * (0.03 + 0.97 * day);
		lit = lit * tr + (1.0 - tr) * sunlight * 0.7;
	}	o_color = vec4(pow(clamp(lit, 0.0, 1.0), vec3(1.0 / 2.2)), 1.0);
}
