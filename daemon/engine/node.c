/* node — parameter parsing with content hashing, node initialisation, worker scratch. */
#include "node.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <xxhash.h>

#include "common/errbuf.h"
#include "common/xalloc.h"

void *gen_scratch(struct gen_ctx *g, size_t n)
{
	if (n > g->cap) {
		free(g->scratch);
		g->cap = n + n / 4;
		g->scratch = xaligned_alloc(64, g->cap);
	}
	return g->scratch;
}

void gen_ctx_fini(struct gen_ctx *g)
{
	free(g->scratch);
	g->scratch = NULL;
	g->cap = 0;
}

int np_error(struct node_parse *p, const char *key, const char *fmt, ...)
{
	struct ini_entry *e = key ? ini_find(p->sec, key) : NULL;
	va_list ap;
	va_start(ap, fmt);
	err_vset_at(p->err, p->file, e ? e->line : p->sec->line, key, fmt, ap);
	va_end(ap);
	return -EINVAL;
}

void np_hash_bytes(struct node_parse *p, const void *data, size_t n)
{
	XXH3_64bits_update(p->hash_state, data, n);
}

static void hash_key(struct node_parse *p, const char *key)
{
	np_hash_bytes(p, key, strlen(key) + 1);
}

static struct ini_entry *take(struct node_parse *p, const char *key)
{
	struct ini_entry *e = ini_find(p->sec, key);
	if (e)
		e->used = true;
	return e;
}

static int parse_double(const char *s, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	while (*end == ' ' || *end == '\t')
		end++;
	if (end == s || *end != '\0' || errno == ERANGE || !isfinite(v))
		return -EINVAL;
	*out = v;
	return 0;
}

int np_double(struct node_parse *p, const char *key, double def, double lo, double hi, double *out)
{
	struct ini_entry *e = take(p, key);
	double v = def;
	if (e) {
		if (parse_double(e->value, &v))
			return np_error(p, key, "expected a number, got \"%s\"", e->value);
		if (v < lo || v > hi)
			return np_error(p, key, "%g is out of range [%g, %g]", v, lo, hi);
	}
	if (v == 0.0)
		v = 0.0; /* -0 and 0 hash alike */
	hash_key(p, key);
	np_hash_bytes(p, &v, sizeof v);
	*out = v;
	return 0;
}

int np_int(struct node_parse *p, const char *key, long def, long lo, long hi, long *out)
{
	struct ini_entry *e = take(p, key);
	long v = def;
	if (e) {
		char *end;
		errno = 0;
		v = strtol(e->value, &end, 0);
		if (end == e->value || *end != '\0' || errno == ERANGE)
			return np_error(p, key, "expected an integer, got \"%s\"", e->value);
		if (v < lo || v > hi)
			return np_error(p, key, "%ld is out of range [%ld, %ld]", v, lo, hi);
	}
	hash_key(p, key);
	int64_t h = v;
	np_hash_bytes(p, &h, sizeof h);
	*out = v;
	return 0;
}

int np_string(struct node_parse *p, const char *key, const char *def, const char **out)
{
	struct ini_entry *e = take(p, key);
	const char *v = e ? e->value : def;
	hash_key(p, key);
	if (v)
		np_hash_bytes(p, v, strlen(v) + 1);
	else
		np_hash_bytes(p, "\xff", 1);
	*out = v;
	return 0;
}

int np_enum(struct node_parse *p, const char *key, const char *const *names, int def, int *out)
{
	struct ini_entry *e = take(p, key);
	int v = def;
	if (e) {
		v = -1;
		for (int i = 0; names[i]; i++)
			if (strcmp(names[i], e->value) == 0)
				v = i;
		if (v < 0) {
			char list[160] = "";
			for (int i = 0; names[i]; i++) {
				size_t l = strlen(list);
				snprintf(list + l, sizeof list - l, "%s%s", i ? ", " : "", names[i]);
			}
			return np_error(p, key, "\"%s\" is not one of: %s", e->value, list);
		}
	}
	hash_key(p, key);
	int32_t h = v;
	np_hash_bytes(p, &h, sizeof h);
	*out = v;
	return 0;
}

static int parse_color(const char *s, uint8_t out[4])
{
	if (s[0] == '#') {
		size_t n = strlen(s + 1);
		if (n != 6 && n != 8)
			return -EINVAL;
		unsigned v[4] = { 0, 0, 0, 255 };
		for (size_t i = 0; i < n / 2; i++) {
			char hex[3] = { s[1 + 2 * i], s[2 + 2 * i], 0 };
			char *end;
			v[i] = (unsigned)strtoul(hex, &end, 16);
			if (*end)
				return -EINVAL;
		}
		for (int i = 0; i < 4; i++)
			out[i] = (uint8_t)v[i];
		return 0;
	}
	double v[4] = { 0, 0, 0, 255 };
	int n = 0;
	const char *q = s;
	while (*q && n < 5) {
		char *end;
		double d = strtod(q, &end);
		if (end == q || d < 0 || d > 255)
			return -EINVAL;
		if (n < 4)
			v[n] = d;
		n++;
		while (*end == ' ' || *end == '\t')
			end++;
		if (*end == ',')
			end++;
		else if (*end)
			return -EINVAL;
		q = end;
	}
	if (n < 3 || n > 4)
		return -EINVAL;
	for (int i = 0; i < 4; i++)
		out[i] = (uint8_t)lrint(v[i]);
	return 0;
}

int np_color(struct node_parse *p, const char *key, const uint8_t def[4], uint8_t out[4])
{
	struct ini_entry *e = take(p, key);
	uint8_t v[4];
	memcpy(v, def, 4);
	if (e && parse_color(e->value, v))
		return np_error(p, key, "expected \"#rrggbb\", \"#rrggbbaa\" or \"r,g,b[,a]\" "
				"(0-255), got \"%s\"", e->value);
	hash_key(p, key);
	np_hash_bytes(p, v, 4);
	memcpy(out, v, 4);
	return 0;
}

int np_doubles(struct node_parse *p, const char *key, double *out, int max, int *n)
{
	struct ini_entry *e = take(p, key);
	*n = 0;
	hash_key(p, key);
	if (!e)
		return 0;
	const char *q = e->value;
	while (*q) {
		while (*q == ' ' || *q == '\t' || *q == ',')
			q++;
		if (!*q)
			break;
		char *end;
		double d = strtod(q, &end);
		if (end == q || !isfinite(d))
			return np_error(p, key, "expected a list of numbers, got \"%s\"", e->value);
		if (*n >= max)
			return np_error(p, key, "more than %d numbers", max);
		if (*end && *end != ' ' && *end != '\t' && *end != ',')
			return np_error(p, key, "expected a list of numbers, got \"%s\"", e->value);
		out[(*n)++] = d;
		q = end;
	}
	np_hash_bytes(p, out, (size_t)*n * sizeof *out);
	return 0;
}

int node_default_deps(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	int m = 0;
	for (int i = 0; i < n->type->nslots && i < NODE_MAX_INPUTS; i++) {
		if (!n->in[i])
			continue;
		out[m].node = n->in[i];
		out[m].key = *k;
		out[m].key.node = n->in[i]->hash;
		m++;
	}
	return m;
}

int node_init(struct node *n, const struct node_type *t, const char *file, struct ini_section *sec,
	      char err[256])
{
	XXH3_state_t *st = XXH3_createState();
	if (!st)
		abort();
	XXH3_64bits_reset(st);
	struct node_parse p = { .file = file, .sec = sec, .hash_state = st, .err = err };
	n->type = t;
	np_hash_bytes(&p, t->name, strlen(t->name) + 1);
	np_hash_bytes(&p, &t->version, sizeof t->version);
	for (int i = 0; i < t->nslots; i++) {
		uint64_t h = n->in[i] ? n->in[i]->hash : 0;
		np_hash_bytes(&p, &h, sizeof h);
		if (n->in[i] && t->slots[i].type != PIX_NONE && n->in[i]->out != t->slots[i].type) {
			np_error(&p, t->slots[i].name, "node \"%s\" gives %s tiles, but %s.%s needs %s",
				 n->in[i]->name, pix_type_name(n->in[i]->out), t->name,
				 t->slots[i].name, pix_type_name(t->slots[i].type));
			XXH3_freeState(st);
			return -EINVAL;
		}
		if (!n->in[i] && !t->slots[i].optional) {
			np_error(&p, NULL, "node \"%s\" (type %s) needs input \"%s\"", n->name, t->name,
				 t->slots[i].name);
			XXH3_freeState(st);
			return -EINVAL;
		}
	}
	int rc = t->create(n, &p);
	if (rc == 0) {
		for (size_t i = 0; i < sec->n; i++) {
			if (!sec->entries[i].used) {
				rc = np_error(&p, sec->entries[i].key, "unknown key for node type %s",
					      t->name);
				break;
			}
		}
		if (rc == 0 && n->out == PIX_NONE)
			rc = np_error(&p, NULL, "node type %s did not set its output type", t->name);
	}
	n->hash = XXH3_64bits_digest(st);
	if (n->hash == 0)
		n->hash = 1; /* 0 means "unknown" in tile keys */
	XXH3_freeState(st);
	if (rc && t->destroy) {
		t->destroy(n);
		n->impl = NULL;
	}
	return rc;
}

void node_free_impl(struct node *n)
{
	free(n->impl);
	n->impl = NULL;
}

int node_opt_height_input(const struct node *n, struct tile *const *in, int nin, uint32_t T,
			  const struct tile **src)
{
	*src = NULL;
	if (!n->in[0])
		return 0;
	if (nin < 1 || !in[0] || in[0]->type != PIX_HEIGHT || in[0]->size != T)
		return -EINVAL;
	*src = in[0];
	return 0;
}

void node_fini(struct node *n)
{
	if (n->type && n->type->destroy)
		n->type->destroy(n);
	n->impl = NULL;
}

double node_gen_bound_ms(int i) { return 0.25 * (double)(1u << i); }

void node_count_generation(struct node *n, uint64_t ns)
{
	int b = 0;
	while (b < NODE_GEN_BUCKETS - 1 && (double)ns > node_gen_bound_ms(b) * 1e6)
		b++;
	atomic_fetch_add(&n->generated, 1);
	atomic_fetch_add(&n->gen_ns, ns);
	atomic_fetch_add(&n->gen_hist[b], 1);
}

static bool among(const struct node *n, const struct node *const *set, int ns)
{
	for (int i = 0; i < ns; i++)
		if (set[i] == n)
			return true;
	return false;
}

/* Adds every node reachable from n to seen[] (up to cap entries; a deeper graph is cut),
 * not going past a node in stop[0..nstop) (nor adding it), nor, with lazy_too false, along
 * an input the node makes lazily (a type with the default deps, whose lazy bits are its
 * present inputs in slot order): work behind such an edge is not "needed anyway". */
static void reach(const struct node *n, const struct node **seen, int *ns, int cap,
		  const struct node *const *stop, int nstop, bool lazy_too)
{
	if (!n || among(n, seen, *ns) || among(n, stop, nstop) || *ns == cap)
		return;
	seen[(*ns)++] = n;
	uint32_t lazy = 0;
	if (!lazy_too && n->type && n->type->lazy && n->type->needed && !n->type->deps)
		lazy = n->type->lazy(n, NULL);
	for (int i = 0, d = 0; i < NODE_MAX_INPUTS; i++) {
		if (!n->in[i])
			continue;
		if (!(lazy & 1u << d++))
			reach(n->in[i], seen, ns, cap, stop, nstop, lazy_too);
	}
}

bool node_exclusive_costly(const struct node *from, const struct node *const *others, int n)
{
	enum { CAP = 1024 };
	const struct node **shared = xmalloc(2 * CAP * sizeof *shared), **mine = shared + CAP;
	int ns = 0, nm = 0;
	for (int i = 0; i < n; i++)
		reach(others[i], shared, &ns, CAP, NULL, 0, false);
	/* what only b needs: a node the others need anyway is theirs, with all below it */
	reach(from, mine, &nm, CAP, shared, ns, true);
	bool costly = false;
	for (int i = 0; i < nm && !costly; i++)
		costly = mine[i]->type && mine[i]->type->costly;
	free(shared);
	return costly;
}
