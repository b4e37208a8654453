/* metrics — see metrics.h. */
#include "metrics.h"

#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <stdatomic.h>
#include <string.h>

#include "common/strbuf.h"

/* The last dotted component names what is counted. */
static bool is_counter(const char *key)
{
	static const char *const ev[] = { "total",   "generated", "merged",	  "cancelled",
					  "failed",  "hits",	  "misses",	  "inserts",
					  "evictions", "loaded",  "puts",	  "corrupt",
					  "write_drops", "write_errors", "sent", "dropped",
					  "stale",   "refused",	  "auth_failures", "requests",
					  "writes",  "drops",	  "bad",	  "waits",
					  "takeovers", "errors", "expired", "handshakes", "reloads", "skipped" };
	const char *last = strrchr(key, '.');
	last = last ? last + 1 : key;
	for (size_t i = 0; i < sizeof ev / sizeof ev[0]; i++)
		if (!strcmp(last, ev[i]))
			return true;
	return false;
}

/* name ← key with [^a-zA-Z0-9_] as '_'; the unit suffix _ms/_us/_s becomes _seconds with the
 * factor to apply. */
static void metric_name(const char *key, char *out, size_t cap, double *scale)
{
	size_t n = 0;
	*scale = 1;
	for (const char *s = key; *s && n + 1 < cap; s++) {
		char c = *s;
		out[n++] = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9')
				   ? c
				   : '_';
	}
	out[n] = '\0';
	static const struct { const char *suf; double k; } units[] = {
		{ "_ms", 1e-3 }, { "_us", 1e-6 }, { "_s", 1 } };
	for (size_t i = 0; i < 3; i++) {
		size_t l = strlen(units[i].suf);
		if (n > l && !strcmp(out + n - l, units[i].suf) && n - l + 8 < cap) {
			strcpy(out + n - l, "_seconds");
			*scale = units[i].k;
			return;
		}
	}
}

static double value(const struct proto_stat *st, double scale)
{
	return (st->kind == PROTO_STAT_U64 ? (double)st->u : st->f) * scale;
}

/* The label value escaped as the format wants (\\, \", \n). */
static void put_label(struct strbuf *b, const char *s, size_t n)
{
	for (size_t i = 0; i < n; i++) {
		if (s[i] == '\\' || s[i] == '"')
			strbuf_printf(b, "\\%c", s[i]);
		else if (s[i] == '\n')
			strbuf_printf(b, "\\n");
		else
			strbuf_printf(b, "%c", s[i]);
	}
}

/* Per-node keys: node.PLANET.NODE.WHAT (planet and node names have no dots). */
static void put_nodes(struct strbuf *b, const struct proto_stat *items, size_t n, const char *what)
{
	char name[160];
	double scale;
	char key[64];
	snprintf(key, sizeof key, "node.%s", what);
	metric_name(key, name, sizeof name, &scale);
	bool counter = is_counter(what), any = false;
	for (size_t i = 0; i < n; i++) {
		const char *k = items[i].key;
		if (strncmp(k, "node.", 5) || items[i].kind == PROTO_STAT_STR)
			continue;
		const char *pl = k + 5, *nd = strchr(pl, '.'), *wh = nd ? strrchr(nd + 1, '.') : NULL;
		if (!nd || !wh || wh == nd || strcmp(wh + 1, what))
			continue;
		if (!any) {
			strbuf_printf(b, "# HELP clipmapd_%s%s %s per node of each planet.\n", name,
			    counter ? "_total" : "", counter ? "Tiles generated" : "Mean generation time");
			strbuf_printf(b, "# TYPE clipmapd_%s%s %s\n", name, counter ? "_total" : "",
			    counter ? "counter" : "gauge");
			any = true;
		}
		strbuf_printf(b, "clipmapd_%s%s{planet=\"", name, counter ? "_total" : "");
		put_label(b, pl, (size_t)(nd - pl));
		strbuf_printf(b, "\",node=\"");
		put_label(b, nd + 1, (size_t)(wh - nd - 1));
		strbuf_printf(b, "\"} %.17g\n", value(&items[i], scale));
	}
}

/* Every node's generation times as one Prometheus histogram (cumulative buckets). */
static void put_histograms(struct strbuf *b, const struct planet_set *ps)
{
	strbuf_printf(b, "# HELP clipmapd_node_generate_seconds Time to generate one tile, per "
			 "node of each planet.\n# TYPE clipmapd_node_generate_seconds histogram\n");
	for (size_t i = 0; i < ps->n; i++)
		for (size_t j = 0; j < ps->planets[i]->nnodes; j++) {
			const struct node *nd = ps->planets[i]->nodes[j];
			struct strbuf l = { 0 };
			strbuf_printf(&l, "planet=\"");
			put_label(&l, ps->planets[i]->name, strlen(ps->planets[i]->name));
			strbuf_printf(&l, "\",node=\"");
			put_label(&l, nd->name, strlen(nd->name));
			strbuf_printf(&l, "\"");
			const char *lab = l.s;
			uint64_t cum = 0;
			for (int k = 0; k < NODE_GEN_BUCKETS; k++) {
				cum += atomic_load(&nd->gen_hist[k]);
				if (k < NODE_GEN_BUCKETS - 1)
					strbuf_printf(b, "clipmapd_node_generate_seconds_bucket{%s,le=\"%g\"} %llu\n",
						      lab, node_gen_bound_ms(k) * 1e-3,
						      (unsigned long long)cum);
				else
					strbuf_printf(b, "clipmapd_node_generate_seconds_bucket{%s,le=\"+Inf\"} %llu\n",
						      lab, (unsigned long long)cum);
			}
			strbuf_printf(b, "clipmapd_node_generate_seconds_sum{%s} %.9f\n", lab,
				      (double)atomic_load(&nd->gen_ns) * 1e-9);
			strbuf_printf(b, "clipmapd_node_generate_seconds_count{%s} %llu\n", lab,
				      (unsigned long long)cum);
			free(l.s);
		}
}

char *metrics_format(const struct proto_stat *items, size_t n, const char *version,
		     const struct planet_set *ps, size_t *len)
{
	struct strbuf b = { 0 };
	strbuf_printf(&b, "# HELP clipmapd_build_info The running clipmapd's version.\n"
		"# TYPE clipmapd_build_info gauge\nclipmapd_build_info{version=\"");
	put_label(&b, version, strlen(version));
	strbuf_printf(&b, "\"} 1\n");
	for (size_t i = 0; i < n; i++) {
		const struct proto_stat *st = &items[i];
		if (!strncmp(st->key, "node.", 5) || st->kind == PROTO_STAT_STR)
			continue;
		char name[160];
		double scale;
		metric_name(st->key, name, sizeof name, &scale);
		bool counter = is_counter(st->key);
		/* "sessions.total" is already a _total name; others get the suffix. */
		const char *suf = counter && !strstr(name, "_total") ? "_total" : "";
		strbuf_printf(&b, "# HELP clipmapd_%s%s clipmapd STATS key %s.\n", name, suf, st->key);
		strbuf_printf(&b, "# TYPE clipmapd_%s%s %s\n", name, suf, counter ? "counter" : "gauge");
		strbuf_printf(&b, "clipmapd_%s%s %.17g\n", name, suf, value(st, scale));
	}
	put_nodes(&b, items, n, "generated");
	put_nodes(&b, items, n, "mean_ms");
	if (ps)
		put_histograms(&b, ps);
	return strbuf_take(&b, len);
}
