#version 330 core
// Terrain shading: colour and normal clipmaps sampled per fragment at the fragment's own
// (lon, lat) — recomputed from the interpolated direction, so nothing is interpolated across
// the meridian behind a pole — lit by a sun, hazed by distance.

in vec3 v_delta;
in vec3 v_pos;
in float v_blend;

uniform vec3 u_lat;
uniform float u_T;
uniform vec4 u_pf;
uniform vec2 u_vf;
uniform float u_sf;
uniform vec4 u_pc;
uniform vec2 u_vc;
uniform float u_sc;
uniform vec3 u_sun;      // towards the sun, in the frame with the camera on meridian 0
uniform vec4 u_haze;     // haze colour, 1 / haze distance
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

	// The fragment's local frame in the frame where the camera sits on meridian 0.
	float lat = u_lat.z + g.y, lon = g.x;
	float sp = sin(lat), cp = cos(lat), so = sin(lon), co = cos(lon);
	vec3 E = vec3(-so, co, 0.0);
	vec3 Nn = vec3(-sp * co, -sp * so, cp);
	vec3 U = vec3(cp * co, cp * so, sp);
	vec3 nrm = normalize(en.x * E + en.y * Nn + up * U);
	float diff = max(dot(nrm, u_sun), 0.0);
	float day = smoothstep(-0.1, 0.1, dot(U, u_sun));
	vec3 lit = albedo * (0.06 + 0.94 * diff * day) + albedo * 0.1 * day;

	float haze = 1.0 - exp(-length(v_pos) * u_haze.w);
	lit = mix(lit, u_haze.rgb * (0.25 + 0.75 * day), haze);
	o_color = vec4(pow(clamp(lit, 0.0, 1.0), vec3(1.0 / 2.2)), 1.0);
}
