/* node_constant — the `constant` node type: a uniform tile, either a height in metres
 * (`height = -4000`) or a colour (`color = #rrggbb[aa]` or `r,g,b[,a]`), exactly one of the two.
 * No inputs. The parsed value lives in n->impl (owned, freed by destroy); generate only reads
 * it, so any number of workers may call it at once.
 */
#include <errno.h>
#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"
#include "engine/node_types.h"

struct constant {
	float height;
	uint8_t rgba[4];
};

static int constant_create(struct node *n, struct node_parse *p)
{
	bool has_h = ini_find(p->sec, "height") != NULL;
	struct ini_entry *ce = ini_find(p->sec, "color");
	bool has_c = ce != NULL;
	if (ce && ce->value[0] == '\0')
		return np_error(p, "color", "empty: write \"color = #rrggbb\" or \"color = r,g,b\"");
	if (has_h && has_c)
		return np_error(p, "color", "a constant is either a height or a color, not both");
	if (!has_h && !has_c)
		return np_error(p, NULL, "a constant needs \"height = <metres>\" or "
				"\"color = <#rrggbb[aa] | r,g,b[,a]>\"");
	struct constant c = { 0 };
	int rc;
	if (has_h) {
		double h;
		rc = np_double(p, "height", 0.0, -1e7, 1e7, &h);
		c.height = (float)h;
		n->out = PIX_HEIGHT;
	} else {
		static const uint8_t black[4] = { 0, 0, 0, 255 };
		rc = np_color(p, "color", black, c.rgba);
		n->out = PIX_COLOR;
	}
	if (rc)
		return rc;
	struct constant *impl = xmalloc(sizeof *impl);
	*impl = c;
	n->impl = impl;
	return 0;
}

static int constant_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			     struct tile *const *in, int nin, struct tile *out)
{
	(void)g, (void)k, (void)in, (void)nin;
	const struct constant *c = n->impl;
	if (out->type != n->out)
		return -EINVAL;
	/* one shared buffer for every tile of the value */
	if (n->out == PIX_HEIGHT)
		tile_fill_uniform(out, &c->height);
	else
		tile_fill_uniform(out, c->rgba);
	return 0;
}

const struct node_type node_type_constant = {
	.name = "constant",
	.doc = "a uniform tile: height = <metres> or color = <#rrggbb[aa] | r,g,b[,a]>",
	.version = 1,
	.slots = NULL,
	.nslots = 0,
	.create = constant_create,
	.destroy = node_free_impl,
	.deps = node_default_deps,
	.generate = constant_generate,
};
