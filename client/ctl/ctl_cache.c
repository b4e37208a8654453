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
				"\"bytes\": %u, \"age_s\": ", x->key.node, x->key.lx, x->key.ly,
				x->key.x, x->key.y,
				pix_valid(x->format) ? pix_format_name(x->format) : "?",
				tier_name(x->tier), x->bytes);
			if (x->age_s == UINT32_MAX) /* unknown (the disk tier) */
				fprintf(out, "null}");
			else
				fprintf(out, "%u}", x->age_s);
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
		if (x->age_s == UINT32_MAX)
			snprintf(age, sizeof age, "-");
		else
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

static const char *op_name(uint8_t op)
{
	return op == PROTO_COP_STAT ? "stat" : op == PROTO_COP_PURGE ? "purge"
		: op == PROTO_COP_GC ? "gc" : "verify";
}

static void json_str(FILE *out, const char *s)
{
	fputc('"', out);
	for (const char *q = s; *q; q++)
		fprintf(out, (*q == '"' || *q == '\\') ? "\\%c" : "%c", *q);
	fputc('"', out);
}

static int cmp_row(const void *a, const void *b)
{
	const struct proto_cache_stat_row *x = a, *y = b;
	int c = strcmp(x->planet, y->planet);
	if (!c)
		c = strcmp(x->layer, y->layer);
	if (!c)
		c = (int)x->ly - (int)y->ly;
	if (!c)
		c = (int)x->tier - (int)y->tier;
	return c;
}

static void print_stat(const struct proto_cache_stat_row *r, size_t n, bool json, FILE *out)
{
	uint64_t tiles[4] = { 0 }, bytes[4] = { 0 };
	for (size_t i = 0; i < n; i++) {
		uint8_t t = r[i].tier <= 3 ? r[i].tier : 0;
		tiles[t] += r[i].tiles;
		bytes[t] += r[i].bytes;
	}
	if (json) {
		fprintf(out, "{\"rows\": [");
		for (size_t i = 0; i < n; i++) {
			fprintf(out, "%s\n  {\"planet\": ", i ? "," : "");
			json_str(out, r[i].planet);
			fprintf(out, ", \"layer\": ");
			json_str(out, r[i].layer);
			fprintf(out, ", \"level\": %u, \"tier\": \"%s\", \"tiles\": %" PRIu64
				", \"bytes\": %" PRIu64 "}",
				r[i].ly, tier_name(r[i].tier), r[i].tiles, r[i].bytes);
		}
		fprintf(out, "%s], \"memory\": {\"tiles\": %" PRIu64 ", \"bytes\": %" PRIu64
			"}, \"disk\": {\"tiles\": %" PRIu64 ", \"bytes\": %" PRIu64 "}}\n",
			n ? "\n" : "", tiles[1], bytes[1], tiles[2], bytes[2]);
		return;
	}
	int pw = 6, lw = 5;
	for (size_t i = 0; i < n; i++) {
		int a = (int)strlen(r[i].planet[0] ? r[i].planet : "(none)");
		int b = (int)strlen(r[i].layer[0] ? r[i].layer : "(unused node)");
		pw = a > pw ? a : pw;
		lw = b > lw ? b : lw;
	}
	fprintf(out, "%-*s  %-*s  %5s  %-6s  %12s  %10s\n", pw, "planet", lw, "layer", "level",
		"tier", "tiles", "bytes");
	for (size_t i = 0; i < n; i++) {
		char b[32];
		ctl_fmt_bytes(r[i].bytes, b, sizeof b);
		fprintf(out, "%-*s  %-*s  %5u  %-6s  %12" PRIu64 "  %10s\n", pw,
			r[i].planet[0] ? r[i].planet : "(none)", lw,
			r[i].layer[0] ? r[i].layer : "(unused node)", r[i].ly, tier_name(r[i].tier),
			r[i].tiles, b);
	}
	char mb[32], db[32];
	ctl_fmt_bytes(bytes[1], mb, sizeof mb);
	ctl_fmt_bytes(bytes[2], db, sizeof db);
	fprintf(out, "memory: %" PRIu64 " tiles, %s; disk: %" PRIu64 " tiles, %s\n", tiles[1], mb,
		tiles[2], db);
}

int ctl_cache_op(struct net_conn *c, const struct ctl_cache_op_opts *o, int timeout_ms,
		 FILE *out, char err[256])
{
	uint32_t req = net_next_req(c);
	struct proto_msg q = { .type = PROTO_CACHE_OP,
			       .cache_op = { .req = req, .op = o->op,
					     .planet = o->planet ? o->planet : "",
					     .filter = o->filter, .bbox = o->bbox, .lmin = o->lmin,
					     .lmax = o->lmax, .nrings = o->nrings,
					     .npoints = o->npoints, .rings = o->rings,
					     .points = o->points } };
	int rc = net_send(c, &q, err);
	if (rc)
		return rc;
	int wait = timeout_ms > 0 ? timeout_ms : 600000;
	struct proto_cache_stat_row *rows = NULL;
	size_t n = 0;
	char **strs = NULL; /* the rows' strings, owned */
	size_t nstrs = 0;
	struct proto_cache_done done = { 0 };
	for (;;) {
		struct proto_msg m = { 0 };
		rc = net_recv(c, &m, wait, err);
		if (rc)
			break;
		if (m.type == PROTO_ERROR) {
			net_error_text(c, &m.error, err);
			rc = -net_code_errno(m.error.code);
			proto_msg_fini(&m);
			break;
		}
		bool end = false;
		if (m.type == PROTO_CACHE_STAT && m.cache_stat.req == req) {
			rows = xrealloc(rows, (n + m.cache_stat.count + 1) * sizeof *rows);
			strs = xrealloc(strs, (nstrs + 2 * m.cache_stat.count + 1) * sizeof *strs);
			for (uint32_t i = 0; i < m.cache_stat.count; i++) {
				rows[n] = m.cache_stat.rows[i];
				rows[n].planet = strs[nstrs++] = xstrdup(rows[n].planet);
				rows[n].layer = strs[nstrs++] = xstrdup(rows[n].layer);
				n++;
			}
		} else if (m.type == PROTO_CACHE_DONE && m.cache_done.req == req) {
			done = m.cache_done;
			end = true;
		}
		proto_msg_fini(&m);
		if (end)
			break;
	}
	if (rc == 0) {
		if (n > 1)
			qsort(rows, n, sizeof *rows, cmp_row);
		if (o->op == PROTO_COP_STAT) {
			print_stat(rows, n, o->json, out);
		} else if (o->json) {
			fprintf(out, "{\"op\": \"%s\", \"checked\": %" PRIu64 ", \"removed\": %" PRIu64
				", \"bytes\": %" PRIu64 ", \"corrupt\": %" PRIu64 "}\n",
				op_name(o->op), done.checked, done.removed, done.bytes, done.corrupt);
		} else {
			char b[32];
			ctl_fmt_bytes(done.bytes, b, sizeof b);
			if (o->op == PROTO_COP_VERIFY)
				fprintf(out, "verify: %" PRIu64 " entries checked, %" PRIu64
					" damaged (removed, %s)\n", done.checked, done.corrupt, b);
			else
				fprintf(out, "%s: %" PRIu64 " entries removed (%s) of %" PRIu64
					" on disk\n", op_name(o->op), done.removed, b, done.checked);
		}
		fflush(out);
		if (ferror(out)) {
			err_set(err, "writing the report: %s", strerror(EIO));
			rc = -EIO;
		}
	}
	for (size_t i = 0; i < nstrs; i++)
		free(strs[i]);
	free(strs);
	free(rows);
	return rc;
}
