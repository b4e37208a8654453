/* encq — see encq.h. The table is a chained hash on (tile key, codec) that doubles when it
 * holds twice as many entries as buckets; the LRU list runs from `oldest` to `newest`. Jobs
 * go to the threads through a mutex+cond list (FIFO: the order the sessions' pumps asked,
 * coarse first), results come back through a done list and an eventfd written only on the
 * empty → non-empty transition (as readyq does).
 */
#include "encq.h"

#include <errno.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include "common/proto.h"
#include "common/xalloc.h"
#include "common/xthread.h"

#define TILE_HEAD (PROTO_HDR + 44u)

struct encq {
	encq_wake_fn wake;
	uint64_t budget;
	int evfd;
	/* (loop) the cache */
	struct etile **tab;
	size_t nb, n;
	struct etile *oldest, *newest;
	struct encq_stats st;
	/* the threads */
	pthread_mutex_t mu; /* protects jobs, jobs_tail, done, stop, signalled */
	pthread_cond_t cv;  /* jobs or stop */
	struct etile *jobs, *jobs_tail, *done;
	bool stop, signalled;
	pthread_t *th;
	unsigned nth;
};

struct etile *etile_ref(struct etile *e)
{
	atomic_fetch_add_explicit(&e->refs, 1, memory_order_relaxed);
	return e;
}

void etile_unref(struct etile *e)
{
	if (!e || atomic_fetch_sub_explicit(&e->refs, 1, memory_order_acq_rel) != 1)
		return;
	for (size_t i = 0; i < e->nwait; i++)
		ready_src_unref(e->waiters[i]);
	free(e->waiters);
	tile_unref(e->t);
	free(e->buf);
	free(e);
}

size_t etile_frame_bytes(const struct etile *e)
{
	return TILE_HEAD + (e->ready ? e->len : e->t ? e->t->nbytes : 0);
}

/* Bytes a cached encoding keeps alive. */
static uint64_t held(const struct etile *e)
{
	return e->buf ? e->len : e->t ? e->t->nbytes : 0;
}

/* ---- the encoder threads ------------------------------------------------------------------ */

static void encode(struct tilecodec *tc, struct etile *e)
{
	const struct tile *t = e->t;
	enum tcodec codec = (enum tcodec)e->codec;
	if (codec == TCODEC_NONE) {
		/* what tilecodec_encode makes of `none`, without copying the texels */
		e->enc = (struct tilecodec_hdr){ .format = (uint8_t)t->type, .codec = TCODEC_NONE,
						 .filter = TFILTER_NONE, .size = t->size,
						 .raw_len = (uint32_t)t->nbytes,
						 .checksum = tilecodec_checksum(t->data, t->nbytes) };
		e->payload = t->data;
		e->len = (uint32_t)t->nbytes;
		return;
	}
	bool lossy = tilecodec_is_lossy(codec);
	/* a lossy codec may fall back to zstd (tilecodec_encode_lossy) */
	size_t bound = tilecodec_bound(lossy ? TCODEC_ZSTD : codec, t->nbytes);
	e->buf = xmalloc(bound ? bound : 1);
	ssize_t n = lossy ? tilecodec_encode_lossy(tc, t->type, t->size, codec, &e->lossy, t->data,
						   &e->enc, e->buf, bound)
			  : tilecodec_encode(tc, t->type, t->size, codec,
					     tilecodec_default_filter(t->type), 1, t->data, &e->enc,
					     e->buf, bound);
	if (n < 0) {
		e->err = (int)n;
		free(e->buf);
		e->buf = NULL;
		return;
	}
	e->len = (uint32_t)n;
	if ((size_t)n < bound / 2)
		e->buf = xrealloc(e->buf, (size_t)n ? (size_t)n : 1); /* the bound was generous */
	e->payload = e->buf;
}

static void *encoder(void *arg)
{
	struct encq *q = arg;
	xthread_batch("encoder");
	struct tilecodec *tc = tilecodec_create();
	xmutex_lock(&q->mu);
	for (;;) {
		while (!q->jobs && !q->stop)
			xcond_wait(&q->cv, &q->mu);
		if (q->stop)
			break;
		struct etile *e = q->jobs;
		q->jobs = e->qnext;
		if (!q->jobs)
			q->jobs_tail = NULL;
		xmutex_unlock(&q->mu);
		encode(tc, e);
		xmutex_lock(&q->mu);
		e->qnext = q->done;
		q->done = e;
		if (!q->signalled) {
			q->signalled = true;
			uint64_t one = 1;
			/* a failed write of a non-blocking eventfd only means it is readable */
			ssize_t w = write(q->evfd, &one, sizeof one);
			(void)w;
		}
	}
	xmutex_unlock(&q->mu);
	tilecodec_destroy(tc);
	return NULL;
}

int encq_create(unsigned nthreads, uint64_t budget, encq_wake_fn wake, struct encq **out)
{
	*out = NULL;
	struct encq *q = xcalloc(1, sizeof *q);
	q->wake = wake;
	q->budget = budget;
	q->nb = 1024;
	q->tab = xcalloc(q->nb, sizeof *q->tab);
	q->evfd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	xmutex_init(&q->mu);
	xcond_init(&q->cv);
	if (q->evfd < 0) {
		int rc = -errno;
		encq_destroy(q);
		return rc;
	}
	nthreads = nthreads ? nthreads : 1;
	q->th = xcalloc(nthreads, sizeof *q->th);
	for (; q->nth < nthreads; q->nth++) {
		int rc = xthread_create(&q->th[q->nth], encoder, q);
		if (rc) {
			encq_destroy(q);
			return rc;
		}
	}
	*out = q;
	return 0;
}

int encq_fd(const struct encq *q)
{
	return q->evfd;
}

/* ---- the cache (loop) --------------------------------------------------------------------- */

static size_t slot(const struct encq *q, const struct tile_key *k, uint8_t codec)
{
	uint64_t h = k->node ^ ((uint64_t)k->lx << 56) ^ ((uint64_t)k->ly << 48) ^
		     ((uint64_t)k->x << 24) ^ k->y ^ ((uint64_t)codec << 62);
	h ^= h >> 33;
	h *= 0xff51afd7ed558ccdull;
	h ^= h >> 33;
	h *= 0xc4ceb9fe1a85ec53ull;
	h ^= h >> 33;
	return (size_t)h & (q->nb - 1);
}

static bool same_key(const struct tile_key *a, const struct tile_key *b)
{
	return a->node == b->node && a->lx == b->lx && a->ly == b->ly && a->x == b->x &&
	       a->y == b->y;
}

static void lru_unlink(struct encq *q, struct etile *e)
{
	if (e->older)
		e->older->newer = e->newer;
	else
		q->oldest = e->newer;
	if (e->newer)
		e->newer->older = e->older;
	else
		q->newest = e->older;
	e->older = e->newer = NULL;
}

static void lru_push(struct encq *q, struct etile *e)
{
	e->older = q->newest;
	e->newer = NULL;
	if (q->newest)
		q->newest->newer = e;
	else
		q->oldest = e;
	q->newest = e;
}

static void grow(struct encq *q)
{
	struct etile **old = q->tab;
	size_t onb = q->nb;
	q->nb *= 2;
	q->tab = xcalloc(q->nb, sizeof *q->tab);
	for (size_t i = 0; i < onb; i++) {
		for (struct etile *e = old[i], *next; e; e = next) {
			next = e->hnext;
			size_t h = slot(q, &e->key, e->codec);
			e->hnext = q->tab[h];
			q->tab[h] = e;
		}
	}
	free(old);
}

/* Takes e out of the cache (its reference is the caller's). */
static void remove_entry(struct encq *q, struct etile *e)
{
	struct etile **pp = &q->tab[slot(q, &e->key, e->codec)];
	while (*pp != e)
		pp = &(*pp)->hnext;
	*pp = e->hnext;
	e->hnext = NULL;
	lru_unlink(q, e);
	e->cached = false;
	q->n--;
	q->st.entries--;
	if (e->ready)
		q->st.bytes -= held(e);
}

static void add_waiter(struct etile *e, struct ready_src *src)
{
	if (!src)
		return;
	if (e->nwait == e->capwait) {
		e->capwait = e->capwait ? 2 * e->capwait : 4;
		e->waiters = xrealloc(e->waiters, e->capwait * sizeof *e->waiters);
	}
	e->waiters[e->nwait++] = ready_src_ref(src);
}

struct etile *encq_get(struct encq *q, struct tile *t, enum tcodec codec,
		       const struct tilecodec_lossy_opts *lossy, struct ready_src *src)
{
	size_t h = slot(q, &t->key, (uint8_t)codec);
	for (struct etile *e = q->tab[h]; e; e = e->hnext) {
		if (e->codec == codec && same_key(&e->key, &t->key)) {
			q->st.shared++;
			lru_unlink(q, e);
			lru_push(q, e);
			if (!e->ready)
				add_waiter(e, src);
			return etile_ref(e);
		}
	}
	struct etile *e = xcalloc(1, sizeof *e);
	atomic_init(&e->refs, 3); /* the cache's, the job's, the caller's */
	e->key = t->key;
	e->codec = (uint8_t)codec;
	if (lossy)
		e->lossy = *lossy;
	e->t = tile_ref(t);
	e->cached = true;
	add_waiter(e, src);
	e->hnext = q->tab[h];
	q->tab[h] = e;
	lru_push(q, e);
	q->n++;
	q->st.entries++;
	q->st.queued++;
	if (q->n > 2 * q->nb)
		grow(q);
	xmutex_lock(&q->mu);
	if (q->jobs_tail)
		q->jobs_tail->qnext = e;
	else
		q->jobs = e;
	q->jobs_tail = e;
	xcond_signal(&q->cv);
	xmutex_unlock(&q->mu);
	return e;
}

/* Lets the oldest ready encodings go while the cache holds more than its budget. */
static void apply_budget(struct encq *q)
{
	struct etile *e = q->oldest;
	while (e && q->st.bytes > q->budget) {
		struct etile *next = e->newer;
		if (e->ready) {
			remove_entry(q, e);
			q->st.evicted++;
			etile_unref(e);
		}
		e = next;
	}
}

void encq_drain(struct encq *q)
{
	uint64_t v;
	ssize_t r = read(q->evfd, &v, sizeof v); /* -EAGAIN when nothing came: harmless */
	(void)r;
	xmutex_lock(&q->mu);
	struct etile *done = q->done;
	q->done = NULL;
	q->signalled = false;
	xmutex_unlock(&q->mu);
	/* the list is newest first: reverse it so sessions are woken in the order asked */
	struct etile *list = NULL;
	while (done) {
		struct etile *next = done->qnext;
		done->qnext = list;
		list = done;
		done = next;
	}
	for (struct etile *e = list, *next; e; e = next) {
		next = e->qnext;
		e->qnext = NULL;
		e->ready = true;
		q->st.queued--;
		if (e->err) {
			q->st.failed++;
		} else {
			q->st.encoded++;
			if (e->buf) {
				tile_unref(e->t); /* encoded: the texels are not needed any more */
				e->t = NULL;
			}
		}
		if (e->cached) {
			if (e->err) {
				remove_entry(q, e); /* asked again: tried again */
				etile_unref(e);
			} else {
				q->st.bytes += held(e);
			}
		}
		struct ready_src **w = e->waiters;
		size_t nw = e->nwait;
		e->waiters = NULL;
		e->nwait = e->capwait = 0;
		for (size_t i = 0; i < nw; i++) {
			if (!w[i]->dead)
				q->wake(w[i]->s);
			ready_src_unref(w[i]);
		}
		free(w);
		etile_unref(e); /* the job's */
	}
	apply_budget(q);
}

void encq_stats(const struct encq *q, struct encq_stats *out)
{
	*out = q->st;
}

void encq_destroy(struct encq *q)
{
	if (!q)
		return;
	xmutex_lock(&q->mu);
	q->stop = true;
	xcond_broadcast(&q->cv);
	xmutex_unlock(&q->mu);
	for (unsigned i = 0; i < q->nth; i++)
		xthread_join(q->th[i]);
	free(q->th);
	/* jobs never started and results never drained: their references */
	for (struct etile *e = q->jobs, *next; e; e = next) {
		next = e->qnext;
		etile_unref(e);
	}
	for (struct etile *e = q->done, *next; e; e = next) {
		next = e->qnext;
		e->ready = true;
		etile_unref(e);
	}
	for (struct etile *e = q->oldest, *next; e; e = next) {
		next = e->newer;
		e->cached = false;
		etile_unref(e);
	}
	free(q->tab);
	if (q->evfd >= 0)
		close(q->evfd);
	xcond_destroy(&q->cv);
	xmutex_destroy(&q->mu);
	free(q);
}
