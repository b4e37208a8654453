/* node_ini — a node built from a planet-file snippet, for tests and benches that drive one
 * node type directly (no planet file, no scheduler). Test-only code. */
#ifndef CLIPMAP_TEST_NODE_INI_H
#define CLIPMAP_TEST_NODE_INI_H
#include "engine/node.h"

struct node_ini {
	struct ini_file *ini; /* the parsed snippet (node parameters borrow from it) */
	struct node n;	      /* named by its section ("node x" → "x") */
	struct gen_ctx g;     /* scratch for n's generate() */
};

/* Builds ni->n as type t from the first section of text, on planet pl (borrowed), with inputs
 * in[0..nin) in slot order (borrowed). Returns 0, or -EINVAL with err filled
 * ("file:line: key: message"); call node_ini_fini either way. */
int node_ini_init(struct node_ini *ni, const struct node_type *t, const struct planet *pl,
		  const char *text, struct node *const *in, int nin, char err[256]);
void node_ini_fini(struct node_ini *ni);

#endif
