/* net_stat — see net_stat.h. */
#include "net_stat.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/errbuf.h"
#include "common/proto.h"

int net_stat_u64(struct net_conn *c, const char *key, uint64_t *out, char err[256])
{
	struct proto_msg m = { .type = PROTO_STATS_REQ, .stats_req = { .req = net_next_req(c) } };
	int rc = net_send(c, &m, err);
	if (rc)
		return rc;
	struct proto_msg r = { 0 };
	if ((rc = net_expect(c, PROTO_STATS, &r, 5000, NULL, NULL, err)))
		return rc;
	rc = -ENOENT;
	for (uint16_t i = 0; i < r.stats.count; i++)
		if (strcmp(r.stats.items[i].key, key) == 0) {
			*out = r.stats.items[i].u;
			rc = 0;
		}
	proto_msg_fini(&r);
	if (rc)
		snprintf(err, 256, "no stat %s", key);
	return rc;
}

uint32_t net_want_block(struct proto_want_entry *w, uint32_t n, uint32_t cap, int ly,
			uint32_t x0, uint32_t y0, uint32_t wd, uint32_t h)
{
	for (uint32_t y = y0; y < y0 + h; y++)
		for (uint32_t x = x0; x < x0 + wd; x++)
			for (uint8_t l = 0; l < 2 && n < cap; l++)
				w[n++] = (struct proto_want_entry){
					.layer = l, .cls = PROTO_CLASS_VISIBLE, .lx = (uint8_t)(ly + 1),
					.ly = (uint8_t)ly, .x = x % (2u << ly), .y = y };
	return n;
}

int net_stat_wait_zero(struct net_conn *c, const char *key, int timeout_ms, char err[256])
{
	uint64_t end = clock_now_ms() + (uint64_t)timeout_ms, v;
	for (;;) {
		int rc = net_stat_u64(c, key, &v, err);
		if (rc || v == 0)
			return rc;
		if (clock_now_ms() >= end) {
			err_set(err, "%s still %llu after %d ms", key, (unsigned long long)v,
				timeout_ms);
			return -ETIMEDOUT;
		}
		usleep(20000);
	}
}
