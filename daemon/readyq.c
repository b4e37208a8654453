/* readyq — see readyq.h. The eventfd counter is only a wake-up: `signalled` says whether a
 * write is already pending, so a burst of pushes costs one write and one read. Items are handed
 * to the loop in the order they were pushed.
 */
#include "readyq.h"

#include <errno.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include "common/xalloc.h"
#include "common/xthread.h"

struct ready_src *ready_src_new(struct readyq *q, struct session *s)
{
	struct ready_src *src = xcalloc(1, sizeof *src);
	atomic_init(&src->refs, 1);
	src->s = s;
	src->q = q;
	return src;
}

struct ready_src *ready_src_ref(struct ready_src *src)
{
	atomic_fetch_add_explicit(&src->refs, 1, memory_order_relaxed);
	return src;
}

void ready_src_unref(struct ready_src *src)
{
	if (src && atomic_fetch_sub_explicit(&src->refs, 1, memory_order_acq_rel) == 1)
		free(src);
}

void ready_src_report(struct ready_src *src, const struct tile_key *key, struct tile *t,
		      int err)
{
	struct ready_item it = { .s = src->s, .src = ready_src_ref(src), .key = *key, .err = err };
	if (t) {
		uint64_t q = atomic_load_explicit(&src->queued, memory_order_relaxed);
		if (src->queue_cap && q && q + t->nbytes > src->queue_cap) {
			it.parked = true; /* the first one always goes: the loop is never starved */
		} else {
			it.t = tile_ref(t);
			it.queued = t->nbytes;
			atomic_fetch_add_explicit(&src->queued, it.queued, memory_order_relaxed);
		}
	}
	readyq_push(src->q, &it);
}

void ready_item_taken(struct ready_item *it)
{
	if (it->src && it->queued)
		atomic_fetch_sub_explicit(&it->src->queued, it->queued, memory_order_relaxed);
	it->queued = 0;
}

int readyq_init(struct readyq *q)
{
	*q = (struct readyq){ .evfd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC) };
	if (q->evfd < 0)
		return -errno;
	xmutex_init(&q->mu);
	return 0;
}

void readyq_fini(struct readyq *q)
{
	if (q->evfd < 0)
		return;
	for (size_t i = 0; i < q->n; i++) {
		ready_item_taken(&q->items[i]);
		tile_unref(q->items[i].t);
		ready_src_unref(q->items[i].src);
	}
	free(q->items);
	close(q->evfd);
	xmutex_destroy(&q->mu);
	q->evfd = -1;
}

void readyq_push(struct readyq *q, const struct ready_item *it)
{
	bool wake = false;
	xmutex_lock(&q->mu);
	if (q->n == q->cap) {
		q->cap = q->cap ? q->cap * 2 : 256;
		q->items = xrealloc(q->items, q->cap * sizeof *q->items);
	}
	q->items[q->n++] = *it;
	if (!q->signalled)
		wake = q->signalled = true;
	xmutex_unlock(&q->mu);
	if (wake) {
		uint64_t one = 1;
		ssize_t n = write(q->evfd, &one, sizeof one);
		(void)n; /* EAGAIN means the counter is already non-zero: the loop wakes anyway */
	}
}

struct ready_item *readyq_take(struct readyq *q, size_t *n)
{
	uint64_t v;
	ssize_t r = read(q->evfd, &v, sizeof v);
	(void)r; /* EAGAIN: nothing was signalled since the last take */
	xmutex_lock(&q->mu);
	struct ready_item *batch = q->items;
	*n = q->n;
	q->items = NULL;
	q->n = q->cap = 0;
	q->signalled = false;
	xmutex_unlock(&q->mu);
	return batch;
}

void readyq_purge(struct readyq *q, const struct session *s)
{
	xmutex_lock(&q->mu);
	size_t k = 0;
	for (size_t i = 0; i < q->n; i++) {
		if (q->items[i].s == s) {
			ready_item_taken(&q->items[i]);
			tile_unref(q->items[i].t);
			ready_src_unref(q->items[i].src);
		} else
			q->items[k++] = q->items[i];
	}
	q->n = k;
	xmutex_unlock(&q->mu);
}
