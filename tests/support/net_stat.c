/* net_stat — see net_stat.h. */
#include "net_stat.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "client/net.h"
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
