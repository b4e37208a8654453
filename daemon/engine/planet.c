/* planet — see planet.h. Loading is a series of passes over the INI sections, each stopping at
 * the first error: a syntax pass (unknown sections, duplicate keys, keys outside sections),
 * [planet] settings, node creation and input resolution by name, a cycle check with
 * topological sort (iterative DFS: a long chain cannot overflow the stack), node_init in
 * topological order (inputs first, so their output types and hashes are known), then layers.
 * Not thread-safe while loading; the loaded planet is immutable.
 */
#include "planet.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/geo.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "node_types.h"

/* Loader state for one node, in file order. */
struct lnode {
	struct node *n;
	struct ini_section *sec;
	const struct node_type *t;
	struct ini_entry *slot[NODE_MAX_INPUTS]; /* the entry naming each input, or NULL */
	int in[NODE_MAX_INPUTS];		 /* index of each input in the lnode array, or -1 */
};

struct loader {
	const char *path;
	char *err;
	const struct node_type *const *types;
	struct planet *p;
	struct lnode *ln;
	size_t nln;
};

/* "path:line: key: message"; the line is left out when ≤ 0, the key when NULL. */
static int __attribute__((format(printf, 4, 5)))
cfg_error(struct loader *L, int line, const char *key, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	err_vset_at(L->err, L->path, line, key, fmt, ap);
	va_end(ap);
	return -EINVAL;
}

static int parse_number(const char *s, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end != '\0' || errno == ERANGE || !isfinite(v))
		return -EINVAL;
	*out = v;
	return 0;
}

static int parse_integer(const char *s, long *out)
{
	char *end;
	errno = 0;
	long v = strtol(s, &end, 10);
	if (end == s || *end != '\0' || errno == ERANGE)
		return -EINVAL;
	*out = v;
	return 0;
}

/* "0.0033528" or "1/298.257223563". */
static int parse_flattening(const char *s, double *out)
{
	const char *slash = strchr(s, '/');
	if (!slash)
		return parse_number(s, out);
	char num[64];
	size_t len = (size_t)(slash - s);
	if (len >= sizeof num)
		return -EINVAL;
	memcpy(num, s, len);
	num[len] = '\0';
	while (len > 0 && isspace((unsigned char)num[len - 1]))
		num[--len] = '\0';
	const char *den_s = slash + 1;
	while (isspace((unsigned char)*den_s))
		den_s++;
	double a, b;
	if (parse_number(num, &a) || parse_number(den_s, &b) || b == 0.0)
		return -EINVAL;
	*out = a / b;
	return 0;
}

static bool name_valid(const char *s)
{
	if (!*s)
		return false;
	for (; *s; s++)
		if (!isalnum((unsigned char)*s) && *s != '_' && *s != '.' && *s != '-')
			return false;
	return true;
}

/* If section name s is "KIND" or "KIND NAME", sets *name (possibly "") and returns true. */
static bool section_kind(const char *s, const char *kind, const char **name)
{
	size_t k = strlen(kind);
	if (strncmp(s, kind, k) != 0 || (s[k] != '\0' && !isspace((unsigned char)s[k])))
		return false;
	s += k;
	while (isspace((unsigned char)*s))
		s++;
	*name = s;
	return true;
}

/* How many sections of ini are of kind (see section_kind). */
static size_t count_sections(const struct ini_file *ini, const char *kind)
{
	size_t n = 0;
	for (size_t i = 0; i < ini->n; i++) {
		const char *name;
		if (section_kind(ini->sections[i].name, kind, &name))
			n++;
	}
	return n;
}

/* Unknown sections, keys outside any section, duplicate keys (almost always a mistake in a
 * planet file, and ini_find would silently take the last). */
static int check_syntax(struct loader *L)
{
	const struct ini_file *ini = L->p->ini;
	const struct ini_section *planet_sec = NULL;
	for (size_t i = 0; i < ini->n; i++) {
		const struct ini_section *s = &ini->sections[i];
		const char *name;
		char hdr[80];
		snprintf(hdr, sizeof hdr, "[%s]", s->name);
		if (s->name[0] == '\0') {
			if (s->n > 0)
				return cfg_error(L, s->entries[0].line, s->entries[0].key,
						 "key outside any section (sections: [planet], "
						 "[node NAME], [layer NAME])");
		} else if (strcmp(s->name, "planet") == 0) {
			if (planet_sec)
				return cfg_error(L, s->line, hdr,
						 "duplicate [planet] section (first at line %d)",
						 planet_sec->line);
			planet_sec = s;
		} else if (section_kind(s->name, "node", &name) ||
			   section_kind(s->name, "layer", &name)) {
			if (!name_valid(name))
				return cfg_error(L, s->line, hdr,
						 "bad name \"%s\": use letters, digits, '_', '.' "
						 "and '-'", name);
		} else {
			return cfg_error(L, s->line, hdr,
					 "unknown section (expected [planet], [node NAME] or "
					 "[layer NAME])");
		}
		for (size_t j = 1; j < s->n; j++)
			for (size_t k = 0; k < j; k++)
				if (strcmp(s->entries[j].key, s->entries[k].key) == 0)
					return cfg_error(L, s->entries[j].line, s->entries[j].key,
							 "duplicate key (first set at line %d)",
							 s->entries[k].line);
	}
	return 0;
}

enum body_kind { BODY_UNSET = 0, BODY_WGS84, BODY_SPHERE, BODY_CUSTOM };
static const char *const body_names[] = { "", "wgs84", "sphere", "custom" };

/* The presets of `atmosphere =`: Earth's air (Rayleigh blue, the haze the viewer always drew);
 * Mars' thin dusty air (a butterscotch sky, a third of Earth's haze over a deeper scale
 * height); none (the Moon: a black sky and no haze). */
static const struct {
	const char *name;
	struct planet_look look;
} look_presets[] = {
	{ "none", { .air_density = 0 } },
	{ "earth", { .air_density = 1.0, .air_height = 8000, .air_color = { 133, 173, 222 } } },
	{ "mars", { .air_density = 0.3, .air_height = 11100, .air_color = { 196, 150, 108 } } },
};

int planet_look_preset(const char *name, struct planet_look *out)
{
	for (size_t i = 0; i < sizeof look_presets / sizeof look_presets[0]; i++)
		if (strcmp(name, look_presets[i].name) == 0) {
			*out = look_presets[i].look;
			return 0;
		}
	return -EINVAL;
}

/* A colour as the node parameters write it (node.h np_color) but opaque: "#rrggbb" or
 * "r,g,b" (0-255). */
static int parse_rgb(const char *s, uint8_t out[3])
{
	long v[3];
	if (s[0] == '#') {
		if (strlen(s) != 7)
			return -EINVAL;
		for (int i = 0; i < 3; i++) {
			char hex[3] = { s[1 + 2 * i], s[2 + 2 * i], 0 };
			char *end;
			if (!isxdigit((unsigned char)hex[0]) || !isxdigit((unsigned char)hex[1]))
				return -EINVAL;
			v[i] = strtol(hex, &end, 16);
		}
	} else {
		for (int i = 0; i < 3; i++) {
			char *end;
			while (isspace((unsigned char)*s))
				s++;
			if (!isdigit((unsigned char)*s))
				return -EINVAL;
			errno = 0;
			v[i] = strtol(s, &end, 10);
			if (errno || v[i] > 255)
				return -EINVAL;
			s = end;
			while (isspace((unsigned char)*s))
				s++;
			if (i < 2 && *s++ != ',')
				return -EINVAL;
		}
		if (*s)
			return -EINVAL;
	}
	for (int i = 0; i < 3; i++)
		out[i] = (uint8_t)v[i];
	return 0;
}

/* The look: atmosphere (a preset, default earth) with its parameters overridden one by one,
 * and the sea. */
static int parse_look(struct loader *L, struct ini_section *s)
{
	struct planet_look *k = &L->p->look;
	struct ini_entry *e_air = s ? ini_find(s, "atmosphere") : NULL;
	struct ini_entry *e_dens = s ? ini_find(s, "atmosphere_density") : NULL;
	struct ini_entry *e_h = s ? ini_find(s, "atmosphere_height") : NULL;
	struct ini_entry *e_col = s ? ini_find(s, "atmosphere_color") : NULL;
	struct ini_entry *e_sea = s ? ini_find(s, "sea_level") : NULL;
	if (planet_look_preset(e_air ? e_air->value : "earth", k))
		return cfg_error(L, e_air->line, "atmosphere",
				 "\"%s\" is not one of: none, earth, mars", e_air->value);
	if (!(k->air_density > 0)) {
		struct ini_entry *e = e_dens ? e_dens : e_h ? e_h : e_col;
		if (e)
			return cfg_error(L, e->line, e->key,
					 "atmosphere = none has no air to describe; remove it or "
					 "name a preset (earth, mars) to start from");
	}
	if (e_dens && (parse_number(e_dens->value, &k->air_density) ||
		       !(k->air_density > 0 && k->air_density <= 100)))
		return cfg_error(L, e_dens->line, "atmosphere_density",
				 "expected a number in (0, 100] (1: Earth's haze), got \"%s\"; "
				 "for no air use atmosphere = none",
				 e_dens->value);
	if (e_h && (parse_number(e_h->value, &k->air_height) ||
		    !(k->air_height >= 1 && k->air_height <= 1e6)))
		return cfg_error(L, e_h->line, "atmosphere_height",
				 "expected a scale height of 1 to 1e6 metres, got \"%s\"",
				 e_h->value);
	if (e_col && parse_rgb(e_col->value, k->air_color))
		return cfg_error(L, e_col->line, "atmosphere_color",
				 "expected \"#rrggbb\" or \"r,g,b\" (0-255), got \"%s\"",
				 e_col->value);
	if (e_sea) {
		if (parse_number(e_sea->value, &k->sea_level) || fabs(k->sea_level) > 1e5)
			return cfg_error(L, e_sea->line, "sea_level",
					 "expected metres above the ellipsoid, |x| ≤ 1e5, got "
					 "\"%s\"",
					 e_sea->value);
		k->sea = true;
	}
	struct ini_entry *e_mask = s ? ini_find(s, "sea_mask") : NULL;
	if (e_mask) {
		if (strcmp(e_mask->value, "color_alpha") != 0)
			return cfg_error(L, e_mask->line, "sea_mask",
					 "\"%s\" is not one of: color_alpha", e_mask->value);
		if (!k->sea)
			return cfg_error(L, e_mask->line, "sea_mask",
					 "a mask of where the sea lies needs a sea (sea_level)");
		k->sea_mask = true;
	}
	return 0;
}

/* Every key of [planet] is known (and marked used). */
static int check_planet_keys(struct loader *L, struct ini_section *s)
{
	static const char *const keys[] = { "name",
					    "description",
					    "body",
					    "radius",
					    "flattening",
					    "tile_size",
					    "max_level",
					    "atmosphere",
					    "atmosphere_density",
					    "atmosphere_height",
					    "atmosphere_color",
					    "sea_level",
					    "sea_geoid",
					    "sea_basins",
					    "sea_mask",
					    NULL };
	for (size_t i = 0; s && i < s->n; i++) {
		struct ini_entry *e = &s->entries[i];
		bool known = false;
		for (int k = 0; keys[k]; k++)
			known = known || strcmp(e->key, keys[k]) == 0;
		if (!known)
			return cfg_error(L, e->line, e->key,
					 "unknown key in [planet] (known: name, description, body, "
					 "radius, flattening, tile_size, max_level, atmosphere, "
					 "atmosphere_density, atmosphere_height, atmosphere_color, "
					 "sea_level, sea_geoid, sea_basins, sea_mask)");
		e->used = true;
	}
	return 0;
}

/* name (default: the file's name without .ini) and description. */
static int parse_name(struct loader *L, struct ini_section *s)
{
	struct planet *p = L->p;
	struct ini_entry *e_name = s ? ini_find(s, "name") : NULL;
	struct ini_entry *e_desc = s ? ini_find(s, "description") : NULL;
	if (e_name) {
		if (!e_name->value[0])
			return cfg_error(L, e_name->line, "name", "must not be empty");
		p->name = xstrdup(e_name->value);
	} else {
		const char *base = strrchr(L->path, '/');
		base = base ? base + 1 : L->path;
		size_t len = strlen(base);
		if (len > 4 && strcmp(base + len - 4, ".ini") == 0)
			len -= 4;
		p->name = xmalloc(len + 1);
		memcpy(p->name, base, len);
		p->name[len] = '\0';
	}
	p->description = xstrdup(e_desc ? e_desc->value : "");
	return 0;
}

/* body, radius, flattening: the reference ellipsoid. */
static int parse_body(struct loader *L, struct ini_section *s)
{
	struct planet *p = L->p;
	struct ini_entry *e_body = s ? ini_find(s, "body") : NULL;
	struct ini_entry *e_radius = s ? ini_find(s, "radius") : NULL;
	struct ini_entry *e_flat = s ? ini_find(s, "flattening") : NULL;
	enum body_kind body = BODY_UNSET;
	if (e_body) {
		if (strcmp(e_body->value, "wgs84") == 0)
			body = BODY_WGS84;
		else if (strcmp(e_body->value, "sphere") == 0)
			body = BODY_SPHERE;
		else if (strcmp(e_body->value, "custom") == 0)
			body = BODY_CUSTOM;
		else
			return cfg_error(L, e_body->line, "body",
					 "\"%s\" is not one of: wgs84, sphere, custom", e_body->value);
	} else if (e_radius) {
		body = e_flat ? BODY_CUSTOM : BODY_SPHERE;
	} else if (e_flat) {
		return cfg_error(L, e_flat->line, "flattening",
				 "needs a radius (and body = custom)");
	} else {
		body = BODY_WGS84;
	}
	int body_line = e_body ? e_body->line : s ? s->line : 0;
	p->a = GEO_WGS84_A;
	p->f = GEO_WGS84_F;
	if (body == BODY_WGS84) {
		struct ini_entry *e = e_radius ? e_radius : e_flat;
		if (e)
			return cfg_error(L, e->line, e->key,
					 "body = wgs84 fixes the radius and flattening; remove "
					 "it or use body = custom");
	} else {
		if (!e_radius)
			return cfg_error(L, body_line, "body", "body = %s needs a radius (metres)",
					 body_names[body]);
		if (parse_number(e_radius->value, &p->a) || !(p->a > 0))
			return cfg_error(L, e_radius->line, "radius",
					 "expected a positive number of metres, got \"%s\"",
					 e_radius->value);
		p->f = 0.0;
		if (body == BODY_SPHERE && e_flat)
			return cfg_error(L, e_flat->line, "flattening",
					 "a sphere has no flattening; use body = custom");
		if (body == BODY_CUSTOM) {
			if (!e_flat)
				return cfg_error(L, body_line, "body",
						 "body = custom needs a flattening (e.g. "
						 "\"1/298.257\", or 0)");
			if (parse_flattening(e_flat->value, &p->f) || !(p->f >= 0 && p->f < 1))
				return cfg_error(L, e_flat->line, "flattening",
						 "expected a number in [0, 1) or \"1/N\", got \"%s\"",
						 e_flat->value);
		}
	}
	char gerr[256] = "";
	if (geo_body_create(p->a, p->f, &p->body, gerr))
		return cfg_error(L, body_line, "body", "%s", gerr);
	return 0;
}

/* tile_size and max_level. */
static int parse_grid(struct loader *L, struct ini_section *s)
{
	struct planet *p = L->p;
	struct ini_entry *e_tile = s ? ini_find(s, "tile_size") : NULL;
	struct ini_entry *e_level = s ? ini_find(s, "max_level") : NULL;
	p->tile_size = 256;
	if (e_tile) {
		long v;
		if (parse_integer(e_tile->value, &v) || v < 64 || v > 1024 || (v & (v - 1)))
			return cfg_error(L, e_tile->line, "tile_size",
					 "expected a power of two from 64 to 1024, got \"%s\"",
					 e_tile->value);
		p->tile_size = (uint32_t)v;
	}
	p->max_level = 20;
	if (e_level) {
		long v;
		if (parse_integer(e_level->value, &v) || v < 1 || v > GRID_MAX_LEVEL - 1)
			return cfg_error(L, e_level->line, "max_level",
					 "expected an integer from 1 to %d, got \"%s\"",
					 GRID_MAX_LEVEL - 1, e_level->value);
		p->max_level = (int)v;
	}
	return 0;
}

static int parse_planet(struct loader *L, struct ini_section *s)
{
	int rc;
	if ((rc = check_planet_keys(L, s)) || (rc = parse_name(L, s)) || (rc = parse_body(L, s)) ||
	    (rc = parse_grid(L, s)))
		return rc;
	return parse_look(L, s);
}

static int find_lnode(const struct loader *L, const char *name)
{
	for (size_t i = 0; i < L->nln; i++)
		if (strcmp(L->ln[i].n->name, name) == 0)
			return (int)i;
	return -1;
}

/* Creates a struct node per [node NAME] section, its type and the entries naming inputs. */
static int collect_nodes(struct loader *L)
{
	struct ini_file *ini = L->p->ini;
	size_t cap = count_sections(ini, "node");
	L->ln = xcalloc(cap ? cap : 1, sizeof *L->ln);
	L->p->nodes = xcalloc(cap ? cap : 1, sizeof *L->p->nodes);
	for (size_t i = 0; i < ini->n; i++) {
		struct ini_section *s = &ini->sections[i];
		const char *name;
		if (!section_kind(s->name, "node", &name))
			continue;
		char hdr[80];
		snprintf(hdr, sizeof hdr, "[%s]", s->name);
		int dup = find_lnode(L, name);
		if (dup >= 0)
			return cfg_error(L, s->line, hdr, "duplicate node name \"%s\" (first at line %d)",
					 name, L->ln[dup].sec->line);
		struct node *n = xcalloc(1, sizeof *n);
		n->name = xstrdup(name);
		n->planet = L->p;
		n->line = s->line;
		atomic_init(&n->generated, 0);
		atomic_init(&n->gen_ns, 0);
		struct lnode *l = &L->ln[L->nln++];
		L->p->nodes[L->p->nnodes++] = n;
		l->n = n;
		l->sec = s;
		for (int k = 0; k < NODE_MAX_INPUTS; k++)
			l->in[k] = -1;

		struct ini_entry *te = ini_find(s, "type");
		if (!te)
			return cfg_error(L, s->line, hdr, "missing \"type = ...\"");
		te->used = true;
		l->t = node_types_find_in(L->types, te->value);
		if (!l->t) {
			char list[160] = "";
			for (size_t k = 0; L->types[k]; k++) {
				size_t len = strlen(list);
				snprintf(list + len, sizeof list - len, "%s%s", k ? ", " : "",
					 L->types[k]->name);
			}
			return cfg_error(L, te->line, "type", "unknown node type \"%s\" (known: %s)",
					 te->value, list);
		}
		for (int k = 0; k < l->t->nslots && k < NODE_MAX_INPUTS; k++) {
			struct ini_entry *e = ini_find(s, l->t->slots[k].name);
			if (e)
				e->used = true;
			l->slot[k] = e;
		}
	}
	for (size_t i = 0; i < L->nln; i++) {
		struct lnode *l = &L->ln[i];
		for (int k = 0; k < NODE_MAX_INPUTS; k++) {
			if (!l->slot[k])
				continue;
			l->in[k] = find_lnode(L, l->slot[k]->value);
			if (l->in[k] < 0)
				return cfg_error(L, l->slot[k]->line, l->slot[k]->key,
						 "unknown input node \"%s\"", l->slot[k]->value);
		}
	}
	return 0;
}

/* "cycle: a -> b -> a" for the DFS stack from position j, closing back at stack[j]. */
static int cycle_error(struct loader *L, const int *stack, size_t j, size_t sp,
		       const struct ini_entry *closing)
{
	char path[200] = "";
	size_t len = 0;
	for (size_t i = j; i <= sp; i++) {
		const char *name = L->ln[stack[i < sp ? i : j]].n->name;
		int w = snprintf(path + len, sizeof path - len, "%s%s", i > j ? " -> " : "", name);
		if (w < 0 || (size_t)w >= sizeof path - len) {
			snprintf(path + sizeof path - 5, 5, "...");
			break;
		}
		len += (size_t)w;
	}
	return cfg_error(L, closing->line, closing->key, "cycle: %s", path);
}

/* Orders p->nodes so every node comes after its inputs; refuses cycles. */
static int topo_sort(struct loader *L)
{
	size_t n = L->nln;
	int rc = 0;
	unsigned char *mark = xcalloc(n ? n : 1, 1); /* 0 new, 1 on the stack, 2 done */
	int *stack = xmalloc((n ? n : 1) * sizeof *stack);
	int *next = xmalloc((n ? n : 1) * sizeof *next);
	struct node **order = xmalloc((n ? n : 1) * sizeof *order);
	size_t done = 0;
	for (size_t r = 0; r < n && rc == 0; r++) {
		if (mark[r])
			continue;
		size_t sp = 0;
		stack[sp] = (int)r;
		next[sp++] = 0;
		mark[r] = 1;
		while (sp > 0) {
			struct lnode *l = &L->ln[stack[sp - 1]];
			if (next[sp - 1] < NODE_MAX_INPUTS) {
				int k = next[sp - 1]++;
				int u = l->in[k];
				if (u < 0 || mark[u] == 2)
					continue;
				if (mark[u] == 1) {
					size_t j = 0;
					while (stack[j] != u)
						j++;
					rc = cycle_error(L, stack, j, sp, l->slot[k]);
					break;
				}
				mark[u] = 1;
				stack[sp] = u;
				next[sp++] = 0;
			} else {
				mark[stack[sp - 1]] = 2;
				order[done++] = l->n;
				sp--;
			}
		}
	}
	if (rc == 0)
		memcpy(L->p->nodes, order, n * sizeof *order);
	free(order);
	free(mark);
	free(stack);
	free(next);
	return rc;
}

static int init_nodes(struct loader *L)
{
	struct planet *p = L->p;
	for (size_t i = 0; i < p->nnodes; i++) {
		struct node *n = p->nodes[i];
		size_t li = 0;
		while (L->ln[li].n != n)
			li++;
		struct lnode *l = &L->ln[li];
		for (int k = 0; k < NODE_MAX_INPUTS; k++)
			n->in[k] = l->in[k] >= 0 ? L->ln[l->in[k]].n : NULL;
		int rc = node_init(n, l->t, L->path, l->sec, L->err);
		if (rc) {
			n->type = NULL; /* node_init already released what create made */
			return rc;
		}
		for (int k = 0; k < n->type->nslots && k < NODE_MAX_INPUTS; k++)
			if (n->in[k] && n->type->slots[k].summary && n->in[k]->out == PIX_HEIGHT)
				n->in[k]->summarize = true;
	}
	return 0;
}

/* sea_geoid = NODE: the sea lies on the geoid of that `geoid` node, sea_level above it;
 * sea_basins = NODE: the closed seas of that `open_sea` node lie at their `levels` instead
 * (the Caspian's −28 m). The viewer gets the surface as a 1° lattice (common/seagrid.h): 0.42 m RMS
 * from EGM96's own 15′ grid, 13 m at worst (Hawaii's steep flanks), measured over the whole
 * sphere. A node within 1¼ lattice steps of a closed sea's cell takes its level, so the
 * bilinear surface holds it over the whole sea and its coast cells; a node that has another
 * sea within that reach too is an error (no lattice value could serve both). */
#define SEA_GRID_STEP 1.0
static int parse_sea_grid(struct loader *L, struct ini_section *s)
{
	struct planet *p = L->p;
	struct ini_entry *eg = s ? ini_find(s, "sea_geoid") : NULL;
	struct ini_entry *eb = s ? ini_find(s, "sea_basins") : NULL;
	if (!eg && !eb)
		return 0;
	struct ini_entry *e = eg ? eg : eb;
	if (!p->look.sea)
		return cfg_error(L, e->line, e->key,
				 "a sea that follows a geoid or lies in basins needs sea_level "
				 "(metres above that geoid; 0 for mean sea level)");
	struct node *geoid = NULL, *basins = NULL;
	double N, lev;
	if (eg) {
		geoid = planet_find_node(p, eg->value);
		if (!geoid)
			return cfg_error(L, eg->line, "sea_geoid", "unknown node \"%s\"", eg->value);
		if (!geoid_undulation(geoid, 0, 0, &N))
			return cfg_error(L, eg->line, "sea_geoid",
					 "node \"%s\" is of type %s; sea_geoid names a node of type "
					 "geoid",
					 eg->value, geoid->type ? geoid->type->name : "?");
	}
	if (eb) {
		basins = planet_find_node(p, eb->value);
		if (!basins)
			return cfg_error(L, eb->line, "sea_basins", "unknown node \"%s\"", eb->value);
		if (!open_sea_level(basins, 0, 0, 0, &lev, NULL))
			return cfg_error(L, eb->line, "sea_basins",
					 "node \"%s\" is of type %s; sea_basins names a node of type "
					 "open_sea",
					 eb->value, basins->type ? basins->type->name : "?");
	}
	struct sea_grid *g = &p->look.sea_grid;
	g->rows = (uint16_t)lround(180 / SEA_GRID_STEP) + 1;
	g->cols = (uint16_t)lround(360 / SEA_GRID_STEP);
	g->dm = xmalloc((size_t)g->rows * g->cols * sizeof *g->dm);
	for (int r = 0; r < g->rows; r++)
		for (int c = 0; c < g->cols; c++) {
			double lat = -90 + r * SEA_GRID_STEP, lon = -180 + c * SEA_GRID_STEP;
			N = lev = 0;
			if (geoid)
				geoid_undulation(geoid, lat, lon, &N);
			bool mixed = false;
			if (basins)
				open_sea_level(basins, lat, lon, 1.25 * SEA_GRID_STEP, &lev, &mixed);
			if (mixed) {
				free(g->dm);
				*g = (struct sea_grid){ 0 };
				return cfg_error(L, eb->line, "sea_basins",
						 "node \"%s\": a sea with a level of its own and "
						 "a sea at another level both lie within %g° of "
						 "(%g, %g); the sea's %g° lattice cannot hold both",
						 eb->value, 1.25 * SEA_GRID_STEP, lat, lon,
						 SEA_GRID_STEP);
			}
			double dm = round((N + lev) * 10);
			g->dm[(size_t)r * g->cols + c] =
				(int16_t)(dm > INT16_MAX ? INT16_MAX : dm < -INT16_MAX ? -INT16_MAX : dm);
		}
	return 0;
}

static int parse_layers(struct loader *L)
{
	struct planet *p = L->p;
	struct ini_file *ini = p->ini;
	size_t cap = count_sections(ini, "layer");
	p->layers = xcalloc(cap ? cap : 1, sizeof *p->layers);
	for (size_t i = 0; i < ini->n; i++) {
		struct ini_section *s = &ini->sections[i];
		const char *name;
		if (!section_kind(s->name, "layer", &name))
			continue;
		char hdr[80];
		snprintf(hdr, sizeof hdr, "[%s]", s->name);
		for (size_t j = 0; j < p->nlayers; j++)
			if (strcmp(p->layers[j].name, name) == 0)
				return cfg_error(L, s->line, hdr, "duplicate layer name \"%s\"", name);
		for (size_t j = 0; j < s->n; j++) {
			struct ini_entry *e = &s->entries[j];
			if (strcmp(e->key, "node") != 0 && strcmp(e->key, "format") != 0)
				return cfg_error(L, e->line, e->key,
						 "unknown key in [layer] (known: node, format)");
			e->used = true;
		}
		struct ini_entry *en = ini_find(s, "node");
		if (!en)
			return cfg_error(L, s->line, hdr, "missing \"node = NAME\"");
		struct node *n = planet_find_node(p, en->value);
		if (!n)
			return cfg_error(L, en->line, "node", "unknown node \"%s\"", en->value);
		struct ini_entry *ef = ini_find(s, "format");
		if (ef) {
			enum pix_type t = pix_format_parse(ef->value);
			if (t == PIX_NONE)
				return cfg_error(L, ef->line, "format",
						 "\"%s\" is not one of: f32, rgba8, rg8", ef->value);
			if (t != n->out)
				return cfg_error(L, ef->line, "format",
						 "layer \"%s\" is declared %s, but node \"%s\" gives "
						 "%s (%s) tiles",
						 name, ef->value, n->name, pix_format_name(n->out),
						 pix_type_name(n->out));
		}
		struct planet_layer *ly = &p->layers[p->nlayers++];
		ly->name = xstrdup(name);
		ly->node = n;
		ly->type = n->out;
	}
	if (p->nlayers == 0)
		return cfg_error(L, 0, NULL,
				 "no [layer NAME] section: a planet publishes at least one layer");
	for (size_t i = 0; i < p->nlayers; i++) {
		const struct node *in = node_normal_plain_input(p->layers[i].node);
		p->layers[i].normal_of = -1;
		for (size_t j = 0; in && j < p->nlayers && p->layers[i].normal_of < 0; j++)
			if (p->layers[j].node == in && p->layers[j].type == PIX_HEIGHT)
				p->layers[i].normal_of = (int)j;
	}
	return 0;
}

int planet_load_shared(const char *path, const struct node_type *const *types,
		       struct img_cache *images, struct planet **out, char err[256])
{
	char local[256];
	if (!err)
		err = local;
	err[0] = '\0';
	struct ini_file *ini;
	int rc = ini_load(path, &ini, err);
	if (rc)
		return rc;
	struct planet *p = xcalloc(1, sizeof *p);
	atomic_init(&p->refs, 1);
	p->ini = ini;
	p->images = images ? img_cache_ref(images) : img_cache_create(PLANET_IMAGE_CACHE_MB);
	if (!p->images) {
		err_set(err, "%s: cannot create an image cache", path);
		planet_unref(p);
		return -ENOMEM;
	}
	if (!types)
		types = node_types_all();
	p->path = xstrdup(path);
	const char *slash = strrchr(path, '/');
	if (!slash) {
		p->dir = xstrdup(".");
	} else {
		size_t len = slash == path ? 1 : (size_t)(slash - path);
		p->dir = xmalloc(len + 1);
		memcpy(p->dir, path, len);
		p->dir[len] = '\0';
	}
	struct loader L = { .path = path, .err = err, .types = types, .p = p };
	rc = check_syntax(&L);
	struct ini_section *ps = NULL; /* [planet], the last one */
	for (size_t i = 0; i < ini->n; i++)
		if (strcmp(ini->sections[i].name, "planet") == 0)
			ps = &ini->sections[i];
	if (rc == 0)
		rc = parse_planet(&L, ps);
	if (rc == 0)
		rc = collect_nodes(&L);
	if (rc == 0)
		rc = topo_sort(&L);
	if (rc == 0)
		rc = init_nodes(&L);
	if (rc == 0)
		rc = parse_layers(&L);
	if (rc == 0)
		rc = parse_sea_grid(&L, ps);
	free(L.ln);
	if (rc) {
		planet_unref(p);
		return rc;
	}
	*out = p;
	return 0;
}

int planet_load_types(const char *path, const struct node_type *const *types, struct planet **out,
		      char err[256])
{
	return planet_load_shared(path, types, NULL, out, err);
}

int planet_load(const char *path, struct planet **out, char err[256])
{
	return planet_load_shared(path, NULL, NULL, out, err);
}

void planet_ref(const struct planet *p)
{
	struct planet *m = (struct planet *)p; /* only the atomic count changes */
	if (m && atomic_load_explicit(&m->refs, memory_order_relaxed) > 0)
		atomic_fetch_add_explicit(&m->refs, 1, memory_order_relaxed);
}

static void planet_free(struct planet *p);

void planet_unref(const struct planet *p)
{
	struct planet *m = (struct planet *)p;
	if (m && atomic_load_explicit(&m->refs, memory_order_relaxed) > 0 &&
	    atomic_fetch_sub_explicit(&m->refs, 1, memory_order_acq_rel) == 1)
		planet_free(m);
}

static void planet_free(struct planet *p)
{
	/* Users before their inputs: a type's destroy may still look at its inputs. */
	for (size_t i = p->nnodes; i-- > 0;) {
		struct node *n = p->nodes[i];
		if (n->type)
			node_fini(n);
		free(n->name);
		free(n);
	}
	free(p->nodes);
	for (size_t i = 0; i < p->nlayers; i++)
		free(p->layers[i].name);
	free(p->layers);
	free(p->look.sea_grid.dm);
	img_cache_unref(p->images); /* after the nodes that read through it */
	geo_body_destroy(p->body);
	ini_free(p->ini);
	free(p->name);
	free(p->description);
	free(p->path);
	free(p->dir);
	free(p);
}

char *planet_resolve_path(const struct planet *p, const char *path)
{
	if (path[0] == '/' || !p || !p->dir || !p->dir[0])
		return xstrdup(path);
	size_t a = strlen(p->dir), b = strlen(path);
	char *s = xmalloc(a + b + 2);
	memcpy(s, p->dir, a);
	s[a] = '/';
	memcpy(s + a + 1, path, b + 1);
	return s;
}

struct node *planet_find_node(const struct planet *p, const char *name)
{
	for (size_t i = 0; i < p->nnodes; i++)
		if (strcmp(p->nodes[i]->name, name) == 0)
			return p->nodes[i];
	return NULL;
}

const struct planet_layer *planet_find_layer(const struct planet *p, const char *name)
{
	for (size_t i = 0; i < p->nlayers; i++)
		if (strcmp(p->layers[i].name, name) == 0)
			return &p->layers[i];
	return NULL;
}

/* A dot double-quoted string: quotes and backslashes escaped, newlines as \n. */
static void dot_string(FILE *f, const char *s)
{
	fputc('"', f);
	for (; *s; s++) {
		if (*s == '"' || *s == '\\')
			fputc('\\', f);
		if (*s == '\n')
			fputs("\\n", f);
		else
			fputc(*s, f);
	}
	fputc('"', f);
}

int planet_write_dot(const struct planet *p, FILE *f)
{
	errno = 0;
	fputs("digraph ", f);
	dot_string(f, p->name);
	fputs(" {\n\tgraph [labelloc=t, label=", f);
	dot_string(f, p->description[0] ? p->description : p->name);
	fputs("];\n\tnode [shape=box, fontname=\"sans-serif\"];\n"
	      "\tedge [fontname=\"sans-serif\", fontsize=10];\n",
	      f);
	/* Node names are [A-Za-z0-9_.-]+, so they need no escaping inside quotes. */
	for (size_t i = 0; i < p->nnodes; i++) {
		const struct node *n = p->nodes[i];
		fprintf(f, "\t\"node:%s\" [label=\"%s\\n%s \u2192 %s\"];\n", n->name, n->name,
			n->type->name, pix_type_name(n->out));
	}
	for (size_t i = 0; i < p->nnodes; i++) {
		const struct node *n = p->nodes[i];
		for (int k = 0; k < n->type->nslots && k < NODE_MAX_INPUTS; k++)
			if (n->in[k])
				fprintf(f, "\t\"node:%s\" -> \"node:%s\" [label=\"%s\"];\n", n->name,
					n->in[k]->name, n->type->slots[k].name);
	}
	for (size_t i = 0; i < p->nlayers; i++) {
		const struct planet_layer *l = &p->layers[i];
		fprintf(f,
			"\t\"layer:%s\" [shape=ellipse, style=filled, fillcolor=lightblue, "
			"label=\"layer %s\\n%s\"];\n",
			l->name, l->name, pix_format_name(l->type));
		fprintf(f, "\t\"layer:%s\" -> \"node:%s\" [style=bold];\n", l->name, l->node->name);
	}
	fputs("}\n", f);
	if (fflush(f) != 0 || ferror(f))
		return errno ? -errno : -EIO;
	return 0;
}
