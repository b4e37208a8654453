/* node_ini — a node from a planet-file snippet (node_ini.h). */
#include "node_ini.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "common/ini.h"

int node_ini_init(struct node_ini *ni, const struct node_type *t, const struct planet *pl,
		  const char *text, struct node *const *in, int nin, char err[256])
{
	memset(ni, 0, sizeof *ni);
	int rc = ini_parse("test.ini", text, strlen(text), &ni->ini, err);
	if (rc)
		return rc;
	if (ni->ini->n < 1) {
		snprintf(err, 256, "test.ini: no section");
		return -EINVAL;
	}
	struct ini_section *sec = &ni->ini->sections[0];
	struct ini_entry *e = ini_find(sec, "type");
	if (e)
		e->used = true;
	const char *name = strchr(sec->name, ' ');
	ni->n.name = (char *)(name ? name + 1 : sec->name);
	ni->n.planet = pl;
	for (int i = 0; i < nin && i < NODE_MAX_INPUTS; i++)
		ni->n.in[i] = in[i];
	return node_init(&ni->n, t, "test.ini", sec, err);
}

void node_ini_fini(struct node_ini *ni)
{
	node_fini(&ni->n);
	gen_ctx_fini(&ni->g);
	ini_free(ni->ini);
	ni->ini = NULL;
}
