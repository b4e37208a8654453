/* synth_source — see synth_source.h. */
#include "synth_source.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"

struct synth {
	struct view_source base;
	synth_fill_fn fill;
	void *ctx;
	struct view_want *list;
	size_t n, next, wants;
};

static int synth_want(struct view_source *vs, const struct view_want *w, size_t n,
		      const struct view_focus *f)
{
	(void)f;
	struct synth *s = (struct synth *)vs;
	s->list = xrealloc(s->list, (n ? n : 1) * sizeof *s->list);
	memcpy(s->list, w, n * sizeof *w);
	s->n = n;
	s->next = 0;
	s->wants++;
	return 0;
}

static int synth_poll(struct view_source *vs, struct view_tile *out)
{
	struct synth *s = (struct synth *)vs;
	if (s->next >= s->n)
		return 0;
	const struct view_want *w = &s->list[s->next++];
	uint32_t T = vs->planet.tile_size;
	enum pix_type f = vs->planet.layer[w->layer].format;
	void *data = xcalloc((size_t)T * T, pix_bytes(f));
	if (s->fill)
		s->fill(s->ctx, w, T, f, data);
	*out = (struct view_tile){ w->layer, w->key, f, T, data, 0, data };
	return 1;
}

static int synth_wait(struct view_source *vs, int ms)
{
	(void)ms;
	const struct synth *s = (const struct synth *)vs;
	return s->next < s->n;
}

static void synth_release(struct view_source *vs, struct view_tile *t)
{
	(void)vs;
	free(t->handle);
	t->handle = NULL;
}

static void synth_destroy(struct view_source *vs)
{
	struct synth *s = (struct synth *)vs;
	free(s->list);
	free(s);
}

static const struct view_source_ops synth_ops = { synth_want, synth_poll, synth_wait,
						  synth_release, synth_destroy };

struct view_source *synth_source_create(uint32_t T, int max_level, int nlayers,
					const char *const names[], const enum pix_type formats[],
					synth_fill_fn fill, void *ctx)
{
	struct synth *s = xcalloc(1, sizeof *s);
	s->base.ops = &synth_ops;
	s->fill = fill;
	s->ctx = ctx;
	struct view_planet *p = &s->base.planet;
	snprintf(p->name, sizeof p->name, "synth");
	p->a = 6378137.0;
	p->f = 1 / 298.257223563;
	p->tile_size = T;
	p->max_level = max_level;
	p->nlayers = nlayers < VIEW_MAX_LAYERS ? nlayers : VIEW_MAX_LAYERS;
	for (int i = 0; i < p->nlayers; i++) {
		snprintf(p->layer[i].name, sizeof p->layer[i].name, "%s", names[i]);
		p->layer[i].format = formats[i];
	}
	return &s->base;
}

size_t synth_source_wants(const struct view_source *vs)
{
	return ((const struct synth *)vs)->wants;
}
