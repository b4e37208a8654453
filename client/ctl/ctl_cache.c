/* ctl_cache — see ctl_cache.h. */
#include "ctl_cache.h"

#include <errno.h>
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"
#include "ctl_args.h"
#include "ctl_conn.h"

static const char *layer_name(const struct proto_planet *p, uint64_t node, char *buf, size_t n)
{
	if (p)
		for (uint16_t i = 0; i < p->nlayers; i++)
			if (p->layers[i].node == node)
				return p->layers[i].name;
	snprintf(buf, n, "%016" PRIx64, node);
	return buf;
}


static int cmp_entry(const void *pa, const void *pb)
{
	const struct proto_cache_entry *a = pa, *b = pb;
	if (a->key.node != b->key.node)
		return a->key.node < b->key.node ? -1 : 1;
	if (a->key.ly != b->key.ly)
		return a->key.ly < b->key.ly ? -1 : 1;
	if (a->key.lx != b->key.lx)
		return a->key.lx < b->key.lx ? -1 : 1;
	if (a->key.y != b->key.y)
		return a->key.y < b->key.y ? -1 : 1;
	if (a->key.x != b->key.x)
		return a->key.x < b->key.x ? -1 : 1;
	return 0;
}

static const char *tier_name(uint8_t t)
{
	return t == PROTO_TIER_MEMORY ? "memory" : t == PROTO_TIER_DISK ? "disk"
		: t == PROTO_TIER_REMOTE ? "remote" : "?";
}

int ctl_cache_print(struct proto_cache_entry *e, size_t n, uint64_t total,
		    const struct proto_planet *p, bool json, FILE *out)
{
	if (n > 1)
		qsort(e, n, sizeof *e, cmp_entry);
	char hb[24];
	if (json) {
		fprintf(out, "{\"total\": %" PRIu64 ", \"entries\": [", total);
		for (size_t i = 0; i < n; i++) {
			const struct proto_cache_entry *x = &e[i];
			const char *ln = layer_name(p, x->key.node, hb, sizeof hb);
			fprintf(out, "%s\n  {\"layer\": \"", i ? "," : "");
			for (const char *q = ln; *q; q++) /* layer names are plain, but be safe */
				fprintf(out, (*q == '"' || *q == '\\') ? "\\%c" : "%c", *q);
			fprintf(out, "\", \"node\": \"%016" PRIx64 "\", \"lx\": %u, \"ly\": %u, "
				"\"x\": %u, \"y\": %u, \"format\": \"%s\", \"tier\": \"%s\", "
				"\"bytes\": %u, \"age_s\": %u}", x->key.node, x->key.lx, x->key.ly,
				x->key.x, x->key.y,
				pix_valid(x->format) ? pix_format_name(x->format) : "?",
				tier_name(x->tier), x->bytes, x->age_s);
		}
		fprintf(out, "%s]}\n", n ? "\n" : "");
		return ferror(out) ? -EIO : 0;
	}
	int lw = 5;
	for (size_t i = 0; i < n; i++) {
		int l = (int)strlen(layer_name(p, e[i].key.node, hb, sizeof hb));
		if (l > lw)
			lw = l;
	}
	fprintf(out, "%-*s  %5s  %10s  %10s  %10s  %9s  %-6s\n", lw, "layer", "level", "x", "y",
		"bytes", "age", "tier");
	uint64_t sum = 0;
	for (size_t i = 0; i < n; i++) {
		const struct proto_cache_entry *x = &e[i];
		char lv[16], age[32];
		snprintf(lv, sizeof lv, "%u/%u", x->key.lx, x->key.ly);
		ctl_fmt_duration(x->age_s, age, sizeof age);
		fprintf(out, "%-*s  %5s  %10u  %10u  %10u  %9s  %-6s\n", lw,
			layer_name(p, x->key.node, hb, sizeof hb), lv, x->key.x, x->key.y, x->bytes,
			age, tier_name(x->tier));
		sum += x->bytes;
	}
	char sb[32];
	ctl_fmt_bytes(sum, sb, sizeof sb);
	fprintf(out, "%zu tile%s shown, %s", n, n == 1 ? "" : "s", sb);
	if (total > n)
		fprintf(out, "; %" PRIu64 " match (raise --limit to see more)", total);
	fputc('\n', out);
	return ferror(out) ? -EIO : 0;
}

int ctl_cache_ls(struct net_conn *c, const struct ctl_cache_opts *o, int timeout_ms, FILE *out,
		 char err[256])
{
	struct proto_msg op = { 0 };
	int rc = net_open_planet(c, o->planet, &op, timeout_ms, err);
	if (rc)
		return rc;
	uint32_t req = net_next_req(c);
	struct proto_msg ls = { .type = PROTO_CACHE_LS,
				.cache_ls = { .req = req, .filter = PROTO_CLS_PLANET,
					      .planet = o->planet, .limit = o->limit } };
	if (o->level >= 0) {
		ls.cache_ls.filter |= PROTO_CLS_LEVEL;
		ls.cache_ls.lx = PROTO_ANY_LX; /* viewers use several lx per level */
		ls.cache_ls.ly = (uint8_t)o->level;
	}
	if (o->near) {
		ls.cache_ls.filter |= PROTO_CLS_NEAR;
		ls.cache_ls.lon = o->lon;
		ls.cache_ls.lat = o->lat;
		ls.cache_ls.radius_m = o->radius_m;
	}
	rc = net_send(c, &ls, err);
	struct proto_cache_entry *all = NULL;
	size_t n = 0, cap = 0;
	uint64_t total = 0;
	for (bool more = true; rc == 0 && more;) {
		struct proto_msg m = { 0 };
		rc = net_expect(c, PROTO_CACHE_ENTRIES, &m, timeout_ms, NULL, NULL, err);
		if (rc)
			break;
		if (m.cache_entries.req != req) {
			err_set(err, "%s: CACHE_ENTRIES for request %u, expected %u",
				net_peer(c), m.cache_entries.req, req);
			rc = -EPROTO;
			proto_msg_fini(&m);
			break;
		}
		if (n + m.cache_entries.count > cap) {
			cap = (n + m.cache_entries.count) * 2;
			all = xrealloc(all, cap * sizeof *all);
		}
		if (m.cache_entries.count)
			memcpy(all + n, m.cache_entries.entries,
			       m.cache_entries.count * sizeof *all);
		n += m.cache_entries.count;
		total = m.cache_entries.total;
		more = m.cache_entries.more != 0;
		proto_msg_fini(&m);
	}
	if (rc == 0) {
		rc = ctl_cache_print(all, n, total, &op.opened.planet, o->json, out);
		if (rc)
			err_set(err, "writing the listing: %s", strerror(-rc));
	}
	free(all);
	proto_msg_fini(&op);
	return rc;
}
