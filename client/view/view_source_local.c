/* view_source_local — see view_source_local.h. The ready callback (manager thread) appends to
 * a FIFO under `lock` and signals `cond`; poll pops from it. Tiles no longer wanted when they
 * arrive are still delivered: the viewer drops what it does not need.
 */
#include "view_source_local.h"

#include <errno.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "engine/store.h"

struct arrival {
	uint8_t layer;
	struct tile_key key;
	struct tile *t; /* owned reference, NULL on failure */
	int err;
};

struct local {
	struct view_source base;
	struct planet *p;
	struct cache *cache;
	struct store *store; /* NULL without one */
	struct sched *sched;
	struct sched_req *req;
	struct want *wbuf; /* scratch for want lists */
	size_t wcap;
	pthread_mutex_t lock; /* protects q, qhead, qn, qcap */
	pthread_cond_t cond;  /* signalled when an arrival is queued (CLOCK_MONOTONIC) */
	struct arrival *q;
	size_t qhead, qn, qcap;
};

static void on_ready(void *ud, const struct want *w, struct tile *t, int err)
{
	struct local *l = ud;
	int layer = -1;
	for (size_t i = 0; i < l->p->nlayers; i++)
		if (l->p->layers[i].node == w->node)
			layer = (int)i;
	if (layer < 0)
		return;
	xmutex_lock(&l->lock);
	if (l->qhead + l->qn == l->qcap) {
		if (l->qhead > 0) {
			memmove(l->q, l->q + l->qhead, l->qn * sizeof *l->q);
			l->qhead = 0;
		}
		if (l->qn == l->qcap) {
			l->qcap = l->qcap ? 2 * l->qcap : 64;
			l->q = xrealloc(l->q, l->qcap * sizeof *l->q);
		}
	}
	l->q[l->qhead + l->qn++] = (struct arrival){ (uint8_t)layer, w->key, t ? tile_ref(t) : NULL,
						     t ? 0 : (err < 0 ? err : -EIO) };
	xcond_signal(&l->cond);
	xmutex_unlock(&l->lock);
}

static int local_want(struct view_source *s, const struct view_want *w, size_t n,
		      const struct view_focus *focus)
{
	struct local *l = (struct local *)s;
	if (n > l->wcap) {
		l->wcap = n;
		l->wbuf = xrealloc(l->wbuf, n * sizeof *l->wbuf);
	}
	size_t m = 0;
	for (size_t i = 0; i < n; i++) {
		if (w[i].layer >= l->p->nlayers || !grid_key_valid(&w[i].key) ||
		    w[i].key.ly > l->p->max_level)
			return -EINVAL;
		struct node *nd = l->p->layers[w[i].layer].node;
		struct want *o = &l->wbuf[m++];
		o->node = nd;
		o->key = w[i].key;
		o->key.node = nd->hash;
		o->cls = w[i].cls == VIEW_CLASS_VISIBLE ? SCHED_VISIBLE : SCHED_PREFETCH;
	}
	if (focus) {
		struct cache_focus f = { focus->lon, focus->lat };
		cache_set_foci(l->cache, &f, 1, l->p->tile_size);
	}
	return sched_req_want(l->req, l->wbuf, m);
}

static int local_poll(struct view_source *s, struct view_tile *out)
{
	struct local *l = (struct local *)s;
	xmutex_lock(&l->lock);
	if (l->qn == 0) {
		xmutex_unlock(&l->lock);
		return 0;
	}
	struct arrival a = l->q[l->qhead++];
	l->qn--;
	if (l->qn == 0)
		l->qhead = 0;
	xmutex_unlock(&l->lock);
	*out = (struct view_tile){ .layer = a.layer,
				   .key = a.key,
				   .format = l->p->layers[a.layer].type,
				   .size = l->p->tile_size,
				   .texels = a.t ? a.t->data : NULL,
				   .err = a.err,
				   .handle = a.t };
	return 1;
}

static int local_wait(struct view_source *s, int timeout_ms)
{
	struct local *l = (struct local *)s;
	uint64_t deadline = clock_now_ns() + (uint64_t)(timeout_ms > 0 ? timeout_ms : 0) * 1000000u;
	bool more = true;
	xmutex_lock(&l->lock);
	while (l->qn == 0 && more)
		more = xcond_wait_until(&l->cond, &l->lock, deadline);
	int got = l->qn > 0;
	xmutex_unlock(&l->lock);
	return got ? 1 : 0;
}

static void local_release(struct view_source *s, struct view_tile *t)
{
	(void)s;
	tile_unref(t->handle);
	t->handle = NULL;
	t->texels = NULL;
}

static void local_destroy(struct view_source *s)
{
	struct local *l = (struct local *)s;
	if (l->req)
		sched_req_destroy(l->req);
	if (l->sched)
		sched_destroy(l->sched);
	if (l->store)
		store_flush(l->store); /* what is queued is committed before it closes */
	store_destroy(l->store);
	for (size_t i = 0; i < l->qn; i++)
		tile_unref(l->q[l->qhead + i].t);
	free(l->q);
	free(l->wbuf);
	cache_destroy(l->cache);
	planet_unref(l->p);
	xcond_destroy(&l->cond);
	xmutex_destroy(&l->lock);
	free(l);
}

static const struct view_source_ops local_ops = {
	.want = local_want,
	.poll = local_poll,
	.wait = local_wait,
	.release = local_release,
	.destroy = local_destroy,
};

int view_source_local_create(const char *planet_path, const struct view_source_local_opts *o,
			     struct view_source **out, char err[256])
{
	static const struct view_source_local_opts defaults = { .workers = 0 };
	if (!o)
		o = &defaults;
	*out = NULL;
	struct planet *p;
	int rc = planet_load(planet_path, &p, err);
	if (rc < 0)
		return rc;
	if (p->nlayers > VIEW_MAX_LAYERS) {
		err_set(err, "%s: %zu layers, at most %d", planet_path, p->nlayers, VIEW_MAX_LAYERS);
		planet_unref(p);
		return -EINVAL;
	}
	struct local *l = xcalloc(1, sizeof *l);
	l->p = p;
	xmutex_init(&l->lock);
	xcond_init(&l->cond);
	l->base.ops = &local_ops;
	struct view_planet *vp = &l->base.planet;
	snprintf(vp->name, sizeof vp->name, "%s", p->name ? p->name : "");
	vp->a = p->a;
	vp->f = p->f;
	vp->tile_size = p->tile_size;
	vp->max_level = p->max_level;
	vp->look = (struct view_look){ .air_density = p->look.air_density,
				       .air_height = p->look.air_height,
				       .air_color = { p->look.air_color[0], p->look.air_color[1],
						      p->look.air_color[2] },
				       .sea = p->look.sea, .sea_level = p->look.sea_level,
				       .sea_mask = p->look.sea_mask, .sea_grid = p->look.sea_grid };
	vp->nlayers = (int)p->nlayers;
	for (size_t i = 0; i < p->nlayers; i++) {
		snprintf(vp->layer[i].name, sizeof vp->layer[i].name, "%s", p->layers[i].name);
		vp->layer[i].format = p->layers[i].type;
		vp->layer[i].normal_of = p->layers[i].normal_of + 1;
	}
	err[0] = '\0';
	if (o->store && (rc = store_open_file(o->store, o->store_mb, &l->store, err)) < 0) {
		local_destroy(&l->base);
		return rc;
	}
	l->cache = cache_create((o->cache_mb ? o->cache_mb : 512) << 20);
	l->sched = sched_create(&(struct sched_desc){ .cache = l->cache, .workers = o->workers,
						      .store = l->store });
	l->req = sched_req_create(l->sched, on_ready, l);
	*out = &l->base;
	return 0;
}

void view_source_local_report(struct view_source *s, char *line, size_t n)
{
	struct local *l = (struct local *)s;
	struct sched_stats st;
	sched_get_stats(l->sched, &st);
	char sum[256] = "";
	if (l->store)
		store_summary(l->store, sum, sizeof sum);
	snprintf(line, n, "%llu tiles generated, %llu loaded from the store%s%s",
		 (unsigned long long)st.generated, (unsigned long long)st.loaded,
		 l->store ? "; store: " : "", sum);
}
