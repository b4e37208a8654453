/* ctl_status — see ctl_status.h. The table is built as rows (section, label, value) first so
 * the label column can be sized to the longest label before anything is printed. */
#include "ctl_status.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"
#include "ctl_args.h"

struct row {
	char section[64]; /* "" for keys without a dot */
	char label[128];
	char value[160];
};

static bool is_node_key(const char *k)
{
	return (strncmp(k, "node.", 5) == 0 || strncmp(k, "nodes.", 6) == 0) &&
	       strchr(strchr(k, '.') + 1, '.') != NULL;
}

/* "link.ID.FIELD": a session's link figure, for --json; the text shows its line "link.ID". */
static bool is_link_field(const char *k)
{
	if (strncmp(k, "link.", 5) != 0)
		return false;
	const char *p = k + 5;
	while (*p >= '0' && *p <= '9')
		p++;
	return p > k + 5 && *p == '.';
}

static bool ends_with(const char *s, const char *suf)
{
	size_t a = strlen(s), b = strlen(suf);
	return a >= b && strcmp(s + a - b, suf) == 0;
}

static void fmt_f64(double v, char *out, size_t n)
{
	if (!isfinite(v))
		snprintf(out, n, "%s", isnan(v) ? "nan" : v > 0 ? "inf" : "-inf");
	else if (v != 0 && (fabs(v) >= 1e9 || fabs(v) < 1e-3))
		snprintf(out, n, "%.4g", v);
	else
		snprintf(out, n, "%.3f", v);
}

/* The value of a stat, made readable where its name says what it is. */
static void fmt_value(const struct proto_stat *s, char *out, size_t n)
{
	const char *k = s->key;
	bool dur = strcmp(k, "uptime") == 0 || strcmp(k, "uptime_s") == 0 || ends_with(k, ".uptime") ||
		   ends_with(k, ".uptime_s");
	bool bytes = strcmp(k, "bytes") == 0 || strncmp(k, "bytes.", 6) == 0 ||
		     ends_with(k, ".bytes") || strstr(k, ".bytes.") || ends_with(k, "_bytes") ||
		     ends_with(k, ".budget");
	if (s->kind == PROTO_STAT_STR) {
		snprintf(out, n, "%s", s->s ? s->s : "");
	} else if (s->kind == PROTO_STAT_U64) {
		if (dur)
			ctl_fmt_duration((double)s->u, out, n);
		else if (bytes && s->u >= 1024) {
			char h[32];
			ctl_fmt_bytes(s->u, h, sizeof h);
			snprintf(out, n, "%-12" PRIu64 " (%s)", s->u, h);
		} else
			snprintf(out, n, "%" PRIu64, s->u);
	} else if (s->kind == PROTO_STAT_F64) {
		if (dur)
			ctl_fmt_duration(s->f, out, n);
		else
			fmt_f64(s->f, out, n);
	} else {
		snprintf(out, n, "?");
	}
}

static double stat_num(const struct proto_stat *s)
{
	return s->kind == PROTO_STAT_U64 ? (double)s->u : s->kind == PROTO_STAT_F64 ? s->f : NAN;
}

/* Finds key in st; NULL if absent. */
static const struct proto_stat *find(const struct proto_stats *st, const char *key)
{
	for (uint16_t i = 0; i < st->count; i++)
		if (strcmp(st->items[i].key, key) == 0)
			return &st->items[i];
	return NULL;
}

/* Whether some key other than a node's starts with "name.". */
static bool has_section(const struct proto_stats *st, const char *name)
{
	size_t n = strlen(name);
	for (uint16_t i = 0; i < st->count; i++) {
		const char *k = st->items[i].key;
		if (strncmp(k, name, n) == 0 && k[n] == '.' && !is_node_key(k))
			return true;
	}
	return false;
}

static void json_str(FILE *out, const char *s)
{
	fputc('"', out);
	for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
		if (*p == '"' || *p == '\\')
			fprintf(out, "\\%c", *p);
		else if (*p < 0x20)
			fprintf(out, "\\u%04x", *p);
		else
			fputc(*p, out);
	}
	fputc('"', out);
}

static void json_num(FILE *out, double v)
{
	if (isfinite(v))
		fprintf(out, "%.17g", v);
	else
		fputs("null", out);
}

static int print_json(const struct proto_stats *st, FILE *out)
{
	fputs("{", out);
	for (uint16_t i = 0; i < st->count; i++) {
		const struct proto_stat *s = &st->items[i];
		fputs(i ? ",\n  " : "\n  ", out);
		json_str(out, s->key);
		fputs(": ", out);
		if (s->kind == PROTO_STAT_U64)
			fprintf(out, "%" PRIu64, s->u);
		else if (s->kind == PROTO_STAT_F64)
			json_num(out, s->f);
		else if (s->kind == PROTO_STAT_STR)
			json_str(out, s->s ? s->s : "");
		else
			fputs("null", out);
	}
	const struct proto_stat *h = find(st, "cache.hits"), *m = find(st, "cache.misses");
	if (h && m && !find(st, "cache.hit_ratio")) {
		double hv = stat_num(h), mv = stat_num(m);
		fputs(st->count ? ",\n  " : "\n  ", out);
		fputs("\"cache.hit_ratio\": ", out);
		json_num(out, hv + mv > 0 ? hv / (hv + mv) : NAN);
	}
	fputs("\n}\n", out);
	return 0;
}

/* One node table: rows = node names, columns = fields in order of first appearance. */
static void print_nodes(const struct proto_stats *st, int labelw, FILE *out)
{
	enum { MAXF = 8, MAXN = 256 };
	char fields[MAXF][48];
	int nf = 0;
	char (*names)[96] = xcalloc(MAXN, sizeof *names);
	int nn = 0;
	for (uint16_t i = 0; i < st->count; i++) {
		const char *k = st->items[i].key;
		if (!is_node_key(k))
			continue;
		const char *name = strchr(k, '.') + 1, *dot = strrchr(k, '.');
		const char *field = dot + 1;
		int f;
		for (f = 0; f < nf && strcmp(fields[f], field) != 0; f++)
			;
		if (f == nf && nf < MAXF)
			snprintf(fields[nf++], sizeof fields[0], "%s", field);
		size_t nl = (size_t)(dot - name);
		int j;
		for (j = 0; j < nn && (strlen(names[j]) != nl || strncmp(names[j], name, nl)); j++)
			;
		if (j == nn && nn < MAXN)
			snprintf(names[nn++], sizeof names[0], "%.*s", (int)nl, name);
	}
	int colw[MAXF];
	for (int f = 0; f < nf; f++)
		colw[f] = (int)strlen(fields[f]) < 10 ? 10 : (int)strlen(fields[f]);
	fprintf(out, "%-*s", labelw, "nodes");
	for (int f = 0; f < nf; f++)
		fprintf(out, "  %*s", colw[f], fields[f]);
	fputc('\n', out);
	const char *prefix = NULL;
	for (int j = 0; j < nn; j++) {
		fprintf(out, "  %-*s", labelw - 2, names[j]);
		for (int f = 0; f < nf; f++) {
			char key[512], v[64] = "-";
			const struct proto_stat *s = NULL;
			for (int pfx = 0; pfx < 2 && !s; pfx++) {
				prefix = pfx ? "nodes" : "node";
				snprintf(key, sizeof key, "%s.%s.%s", prefix, names[j], fields[f]);
				s = find(st, key);
			}
			if (s) {
				if (s->kind == PROTO_STAT_F64)
					snprintf(v, sizeof v, "%.3f", s->f);
				else
					fmt_value(s, v, sizeof v);
			}
			fprintf(out, "  %*s", colw[f], v);
		}
		fputc('\n', out);
	}
	free(names);
}

int ctl_status_print(const struct proto_stats *st, const char *peer, bool json, FILE *out)
{
	if (json) {
		print_json(st, out);
		return ferror(out) ? -EIO : 0;
	}
	size_t cap = (size_t)st->count + 2, nr = 0;
	struct row *rows = xcalloc(cap, sizeof *rows);
	/* sections in order of first appearance; "" (plain keys) first */
	char (*secs)[64] = xcalloc(cap + 1, sizeof *secs);
	size_t ns = 1;
	bool have_nodes = false;
	for (uint16_t i = 0; i < st->count; i++) {
		const struct proto_stat *s = &st->items[i];
		if (is_node_key(s->key)) {
			have_nodes = true;
			continue;
		}
		if (is_link_field(s->key))
			continue;
		struct row *r = &rows[nr++];
		const char *dot = strchr(s->key, '.');
		if (dot) {
			snprintf(r->section, sizeof r->section, "%.*s", (int)(dot - s->key), s->key);
			snprintf(r->label, sizeof r->label, "%s", dot + 1);
		} else if (has_section(st, s->key)) {
			/* "sessions" with "sessions.total": the value heads its section */
			snprintf(r->section, sizeof r->section, "%s", s->key);
		} else {
			snprintf(r->label, sizeof r->label, "%s", s->key);
		}
		fmt_value(s, r->value, sizeof r->value);
		size_t j;
		for (j = 0; j < ns && strcmp(secs[j], r->section) != 0; j++)
			;
		if (j == ns)
			snprintf(secs[ns++], sizeof secs[0], "%s", r->section);
		/* the hit ratio goes right after whichever of hits/misses comes second */
		if (strcmp(r->section, "cache") == 0 &&
		    (strcmp(r->label, "hits") == 0 || strcmp(r->label, "misses") == 0) &&
		    !find(st, "cache.hit_ratio")) {
			const struct proto_stat *h = find(st, "cache.hits"),
						*m = find(st, "cache.misses");
			const struct proto_stat *other = strcmp(r->label, "hits") == 0 ? m : h;
			if (h && m && other < s) {
				double hv = stat_num(h), mv = stat_num(m);
				struct row *q = &rows[nr++];
				snprintf(q->section, sizeof q->section, "cache");
				snprintf(q->label, sizeof q->label, "hit ratio");
				if (hv + mv > 0)
					snprintf(q->value, sizeof q->value, "%.1f %%",
						 100.0 * hv / (hv + mv));
				else
					snprintf(q->value, sizeof q->value, "-");
			}
		}
	}
	int labelw = 24;
	for (size_t i = 0; i < nr; i++)
		if ((int)strlen(rows[i].label) + 2 > labelw)
			labelw = (int)strlen(rows[i].label) + 2;
	fprintf(out, "clipmapd%s%s\n", peer ? " at " : "", peer ? peer : "");
	for (size_t j = 0; j < ns; j++) {
		if (secs[j][0]) {
			const char *head = "";
			for (size_t i = 0; i < nr; i++)
				if (!rows[i].label[0] && strcmp(rows[i].section, secs[j]) == 0)
					head = rows[i].value;
			if (head[0])
				fprintf(out, "%-*s  %s\n", labelw, secs[j], head);
			else
				fprintf(out, "%s\n", secs[j]);
		}
		for (size_t i = 0; i < nr; i++)
			if (rows[i].label[0] && strcmp(rows[i].section, secs[j]) == 0)
				fprintf(out, "  %-*s  %s\n", labelw - 2, rows[i].label, rows[i].value);
	}
	if (have_nodes)
		print_nodes(st, labelw, out);
	free(secs);
	free(rows);
	return ferror(out) ? -EIO : 0;
}

/* Sends STATS_REQ and receives the STATS into m (finied by the caller on success). */
static int fetch_stats(struct net_conn *c, int timeout_ms, struct proto_msg *m, char err[256])
{
	struct proto_msg req = { .type = PROTO_STATS_REQ, .stats_req = { .req = net_next_req(c) } };
	int rc = net_send(c, &req, err);
	return rc ? rc : net_expect(c, PROTO_STATS, m, timeout_ms, NULL, NULL, err);
}

int ctl_status_run(struct net_conn *c, bool json, int timeout_ms, FILE *out, char err[256])
{
	struct proto_msg m = { 0 };
	int rc = fetch_stats(c, timeout_ms, &m, err);
	if (rc)
		return rc;
	rc = ctl_status_print(&m.stats, net_peer(c), json, out);
	if (rc)
		err_set(err, "writing the status: %s", strerror(-rc));
	proto_msg_fini(&m);
	return rc;
}

int ctl_stat_u64(struct net_conn *c, const char *key, int timeout_ms, uint64_t *v, char err[256])
{
	struct proto_msg m = { 0 };
	int rc = fetch_stats(c, timeout_ms, &m, err);
	if (rc)
		return rc;
	const struct proto_stat *s = find(&m.stats, key);
	if (s && s->kind == PROTO_STAT_U64)
		*v = s->u;
	else
		err_set(err, "%s: no figure \"%s\"", net_peer(c), key);
	rc = s && s->kind == PROTO_STAT_U64 ? 0 : -ENOENT;
	proto_msg_fini(&m);
	return rc;
}

int ctl_status_planets(struct net_conn *c, int timeout_ms, FILE *out, char err[256])
{
	struct proto_msg req = { .type = PROTO_LIST_PLANETS,
				 .list_planets = { .req = net_next_req(c) } };
	int rc = net_send(c, &req, err);
	if (rc)
		return rc;
	struct proto_msg m = { 0 };
	rc = net_expect(c, PROTO_PLANETS, &m, timeout_ms, NULL, NULL, err);
	if (rc)
		return rc;
	fprintf(out, "planets served (%u)\n", (unsigned)m.planets.count);
	for (uint16_t i = 0; i < m.planets.count; i++) {
		const struct proto_planet *p = &m.planets.planets[i];
		fprintf(out, "  %-22s  %u layer%s, levels 0-%u, %.0f km radius\n", p->name,
			(unsigned)p->nlayers, p->nlayers == 1 ? "" : "s", (unsigned)p->max_level,
			p->a / 1000);
	}
	proto_msg_fini(&m);
	if (ferror(out)) {
		err_set(err, "writing the status: %s", strerror(EIO));
		return -EIO;
	}
	return 0;
}
