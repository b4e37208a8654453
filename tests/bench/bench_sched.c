/* Scheduler overhead: tiles per second through manager and workers for a node that does
 * (almost) nothing or spins 1 us, the manager thread's CPU per tile (the serial work: the
 * scheduler's ceiling is 1 / that), the whole process's CPU per tile less generation (the
 * hand-off cost), the speed-up those project at 16 and 64 cores, and the latency from
 * sched_req_want to the callback for a cached tile. Prints one line per figure, and the
 * `sched/goal` lines: issue 20's goals beside the median of three runs.
 *
 * CPU times come from the kernel's per-thread clocks, so they hold on a loaded machine where
 * tiles/s does not. The manager is the first thread sched_create starts (sched.c), found as
 * the lowest new thread id. To compare with another scheduler, link this program against its
 * sched.o and jobtab.o (docs/ARCHITECTURE.md, "Threads and what each owns", has figures of
 * the scheduler before and after issue 20 measured that way). */
#include <dirent.h>
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/xthread.h"
#include "engine/cache.h"
#include "engine/node.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "engine/tile.h"

static int gen_cheap(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		     struct tile *const *in, int nin, struct tile *out)
{
	(void)n, (void)g, (void)k, (void)in, (void)nin;
	tile_f32(out)[0] = 1.0f; /* the rest stays uninitialised: we time the machinery */
	return 0;
}

/* The "1 us synthetic node": busy for spin_ns of thread CPU. */
static uint64_t spin_ns;

static uint64_t thread_cpu_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
	return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static int gen_spin(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		    struct tile *const *in, int nin, struct tile *out)
{
	uint64_t end = thread_cpu_ns() + spin_ns;
	while (thread_cpu_ns() < end)
		;
	return gen_cheap(n, g, k, in, nin, out);
}

static const struct node_type t_spin = { .name = "spin", .generate = gen_spin };

static uint64_t process_cpu_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
	return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

/* The CPU clock of thread tid of this process (the kernel's MAKE_THREAD_CPUCLOCK, as glibc's
 * pthread_getcpuclockid builds it). */
static uint64_t tid_cpu_ns(pid_t tid)
{
	clockid_t id = (clockid_t)((~(unsigned)tid << 3) | 6);
	struct timespec ts;
	if (clock_gettime(id, &ts) != 0)
		return 0;
	return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

/* This process's thread ids, in a fixed array; returns how many. */
static size_t list_tids(pid_t *out, size_t cap)
{
	DIR *d = opendir("/proc/self/task");
	size_t n = 0;
	if (!d)
		return 0;
	for (struct dirent *e; (e = readdir(d)) && n < cap;)
		if (e->d_name[0] != '.')
			out[n++] = (pid_t)atoi(e->d_name);
	closedir(d);
	return n;
}

static bool has_tid(const pid_t *a, size_t n, pid_t t)
{
	for (size_t i = 0; i < n; i++)
		if (a[i] == t)
			return true;
	return false;
}

/* sched_create, and the id of the manager thread it started (0 if not found). */
static struct sched *create_traced(const struct sched_desc *d, pid_t *manager)
{
	pid_t before[256], after[256];
	size_t nb = list_tids(before, 256);
	struct sched *s = sched_create(d);
	size_t na = list_tids(after, 256);
	*manager = 0;
	for (size_t i = 0; i < na; i++)
		if (!has_tid(before, nb, after[i]) && (*manager == 0 || after[i] < *manager))
			*manager = after[i];
	return s;
}

static const struct node_type t_cheap = { .name = "cheap", .generate = gen_cheap };

struct counter {
	pthread_mutex_t mu;
	pthread_cond_t cv;
	size_t n, target;
	uint64_t t_ready; /* ns, when the callback reaching target ran */
};

static void on_ready(void *ud, const struct want *w, struct tile *t, int err)
{
	(void)w, (void)t, (void)err;
	struct counter *c = ud;
	xmutex_lock(&c->mu);
	if (++c->n >= c->target) {
		c->t_ready = clock_now_ns(); /* the last one: what the figures need */
		xcond_signal(&c->cv);
	}
	xmutex_unlock(&c->mu);
}

static void wait_count(struct counter *c)
{
	xmutex_lock(&c->mu);
	while (c->n < c->target)
		xcond_wait(&c->cv, &c->mu);
	xmutex_unlock(&c->mu);
}

static void node_setup(struct node *n, struct planet *p, uint64_t hash)
{
	memset(n, 0, sizeof *n);
	n->name = (char *)"cheap";
	n->type = &t_cheap;
	n->out = PIX_HEIGHT;
	n->hash = hash;
	n->planet = p;
	atomic_init(&n->generated, 0);
	atomic_init(&n->gen_ns, 0);
}

/* What both loads start with: a cache, a traced scheduler, and the bulk want list of every
 * tile of node n at level ly (malloc'd, *total entries). Exits on failure. */
struct rig {
	struct cache *c;
	struct sched *s;
	pid_t mtid;
	struct want *w;
	size_t total;
};

static void rig_start(struct rig *g, int workers, struct node *n, int ly)
{
	g->c = cache_create((size_t)512 << 20);
	struct sched_desc d = { .cache = g->c, .workers = workers };
	g->s = create_traced(&d, &g->mtid);
	size_t nx = (size_t)1 << (ly + 1), ny = (size_t)1 << ly;
	g->total = nx * ny;
	g->w = malloc(g->total * sizeof *g->w);
	if (!g->w || !g->s || !g->c) {
		fprintf(stderr, "bench_sched: out of memory\n");
		exit(1);
	}
	size_t i = 0;
	for (uint32_t y = 0; y < ny; y++)
		for (uint32_t x = 0; x < nx; x++) {
			struct tile_key k = { .node = n->hash, .x = x, .y = y,
					      .lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly };
			g->w[i++] = (struct want){ .node = n, .key = k, .cls = SCHED_BULK };
		}
}

static void rig_stop(struct rig *g)
{
	sched_destroy(g->s);
	cache_destroy(g->c);
	free(g->w);
}

struct run {
	size_t tiles;
	double sec;
	double mgr_us;	   /* manager CPU per tile */
	double handoff_us; /* process CPU per tile less the nodes' generation time */
	double gen_us;	   /* generation time per tile */
};

/* One want list of every tile of a level, callbacks counted. */
static struct run throughput(uint32_t T, int workers, int ly, const struct node_type *type)
{
	struct planet p = { .tile_size = T, .max_level = 12 };
	struct node n;
	node_setup(&n, &p, 0x1234 + (uint64_t)T * 31 + (uint64_t)workers + (uint64_t)ly * 7);
	n.type = type;
	struct rig g;
	rig_start(&g, workers, &n, ly);
	struct sched *s = g.s;
	pid_t mtid = g.mtid;
	size_t total = g.total;
	struct counter cnt = { .target = total };
	xmutex_init(&cnt.mu);
	xcond_init(&cnt.cv);
	struct sched_req *r = sched_req_create(s, on_ready, &cnt);
	usleep(20000); /* let the threads start and settle */
	uint64_t m0 = tid_cpu_ns(mtid), p0 = process_cpu_ns(), t0 = clock_now_ns();
	if (sched_req_want(r, g.w, total) != 0) {
		fprintf(stderr, "bench_sched: want refused\n");
		exit(1);
	}
	wait_count(&cnt);
	uint64_t m1 = tid_cpu_ns(mtid), p1 = process_cpu_ns();
	struct run o = { .tiles = total };
	o.sec = (double)(cnt.t_ready - t0) * 1e-9;
	o.mgr_us = (double)(m1 - m0) * 1e-3 / (double)total;
	/* The spin node's CPU is known; generation time is wall time (preemption included). */
	o.gen_us = type == &t_spin ? (double)spin_ns * 1e-3
				   : (double)atomic_load(&n.gen_ns) * 1e-3 / (double)total;
	o.handoff_us = (double)(p1 - p0) * 1e-3 / (double)total - o.gen_us;
	if (!mtid)
		o.mgr_us = -1;
	sched_req_destroy(r);
	rig_stop(&g);
	xmutex_destroy(&cnt.mu);
	xcond_destroy(&cnt.cv);
	return o;
}

static void print_run(const char *what, uint32_t T, int workers, const struct run *o)
{
	printf("sched/throughput %s T=%u %d worker%s: %.0f tiles/s (%zu tiles, %.2f us/tile); "
	       "manager %.2f us/tile; hand-off %.2f us/tile\n",
	       what, T, workers, workers == 1 ? "" : "s", (double)o->tiles / o->sec, o->tiles,
	       o->sec * 1e6 / (double)o->tiles, o->mgr_us, o->handoff_us);
}

/* The speed-up N cores of real synthesis would get with the measured manager time per tile
 * (serial, us) beside work us of worker time per tile: Amdahl's law with serial fraction
 * serial / (serial + work) (pessimistic: the manager overlaps the workers), and the pipeline
 * bound min(N, (serial + work) / serial). */
static void project(double serial, double work)
{
	double f = serial / (serial + work);
	for (int N = 16; N <= 64; N *= 4) {
		double amdahl = 1.0 / (f + (1.0 - f) / N);
		double pipe = (serial + work) / serial;
		printf("sched/projection %d cores, %.0f us/tile nodes, %.2f us serial: Amdahl "
		       "%.1fx (%.0f %%), pipeline bound %.1fx\n",
		       N, work, serial, amdahl, 100.0 * amdahl / N, pipe < N ? pipe : (double)N);
	}
}

/* ---- a daemon-like load: a node graph with shared dependencies, sessions that replace their
 * want lists as they move, and a bulk prefetch underneath ---- */

static struct node base_node, layer_node;

/* Layer tile (x, y) at level ly needs the base tile at the same key and, below level 0, its
 * parent and the parent's two neighbours in x (shared with the tiles around: merges). */
static int layer_deps(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	(void)n;
	int nd = 0;
	struct tile_key b = *k;
	b.node = base_node.hash;
	out[nd++] = (struct node_dep){ &base_node, b };
	if (k->ly > 0)
		for (int dx = -1; dx <= 1; dx++) {
			struct tile_key pk = { .node = layer_node.hash, .lx = (uint8_t)(k->lx - 1),
					       .ly = (uint8_t)(k->ly - 1), .y = k->y / 2 };
			pk.x = grid_wrap_x(pk.lx, (int64_t)(k->x / 2) + dx);
			out[nd++] = (struct node_dep){ &layer_node, pk };
		}
	return nd;
}

static const struct node_type t_layer = { .name = "layer", .generate = gen_cheap,
					  .deps = layer_deps };

#define SESSIONS 8
#define WIN 16 /* a session wants a WIN x WIN window at its level, visible */

struct session_load {
	struct sched *s;
	struct sched_req *req[SESSIONS];
	atomic_bool stop;
	struct counter *bulk;
	uint64_t lists; /* want lists replaced */
	int ly;
};

static void session_list(struct want *w, int ly, uint32_t x0, uint32_t y0)
{
	size_t i = 0;
	for (uint32_t y = 0; y < WIN; y++)
		for (uint32_t x = 0; x < WIN; x++) {
			struct tile_key k = { .node = layer_node.hash, .lx = (uint8_t)(ly + 1),
					      .ly = (uint8_t)ly, .y = y0 + y };
			k.x = grid_wrap_x(k.lx, (int64_t)x0 + x);
			w[i++] = (struct want){ .node = &layer_node, .key = k, .cls = SCHED_VISIBLE };
		}
}

/* Every session moves one tile east each time MOVE_EVERY more bulk tiles are done, replacing
 * its list: as many list changes per tile whatever the machine's load. */
#define MOVE_EVERY 128
static void *move_sessions(void *arg)
{
	struct session_load *L = arg;
	struct want w[WIN * WIN];
	size_t mark = 0;
	for (uint32_t step = 0; !atomic_load(&L->stop); step++) {
		xmutex_lock(&L->bulk->mu);
		bool due = L->bulk->n >= mark;
		xmutex_unlock(&L->bulk->mu);
		if (!due) {
			struct timespec ts = { 0, 50000 };
			nanosleep(&ts, NULL);
			step--; /* not a move */
			continue;
		}
		mark += MOVE_EVERY;
		for (int i = 0; i < SESSIONS; i++) {
			session_list(w, L->ly, step + (uint32_t)i * 97, (uint32_t)i * 13);
			if (sched_req_want(L->req[i], w, WIN * WIN) != 0)
				exit(1);
			L->lists++;
		}
	}
	return NULL;
}

static void on_ready_any(void *ud, const struct want *w, struct tile *t, int err)
{
	(void)w, (void)t, (void)err, (void)ud;
}

/* Bulk prefetch of every layer tile of level bulk_ly (and so every coarser one) while the
 * sessions fly at level bulk_ly + 2. Figures per generated tile. */
static void daemon_like(int workers, int bulk_ly)
{
	struct planet p = { .tile_size = 16, .max_level = 12 };
	node_setup(&base_node, &p, 0xba5e + (uint64_t)workers);
	node_setup(&layer_node, &p, 0x1a7e + (uint64_t)workers);
	layer_node.type = &t_layer;
	layer_node.in[0] = &base_node;
	struct rig g;
	rig_start(&g, workers, &layer_node, bulk_ly);
	struct sched *s = g.s;
	pid_t mtid = g.mtid;
	size_t total = g.total;
	struct session_load L = { .s = s, .ly = bulk_ly + 2 };
	atomic_init(&L.stop, false);
	for (int i = 0; i < SESSIONS; i++)
		L.req[i] = sched_req_create(s, on_ready_any, NULL);
	struct counter cnt = { .target = total };
	xmutex_init(&cnt.mu);
	xcond_init(&cnt.cv);
	struct sched_req *bulk = sched_req_create(s, on_ready, &cnt);
	L.bulk = &cnt;
	usleep(20000);
	pthread_t mover;
	uint64_t m0 = tid_cpu_ns(mtid), p0 = process_cpu_ns(), t0 = clock_now_ns();
	if (xthread_create(&mover, move_sessions, &L) != 0 || sched_req_want(bulk, g.w, total) != 0) {
		fprintf(stderr, "bench_sched: cannot start\n");
		exit(1);
	}
	wait_count(&cnt);
	uint64_t m1 = tid_cpu_ns(mtid), p1 = process_cpu_ns(), t1 = clock_now_ns();
	atomic_store(&L.stop, true);
	xthread_join(mover);
	struct sched_stats st;
	sched_get_stats(s, &st);
	double n = (double)st.generated, sec = (double)(t1 - t0) * 1e-9;
	printf("sched/daemon-like %d workers, %d sessions (%llu lists), bulk level %d: %.0f tiles/s "
	       "(%.0f generated, %llu merged, %llu cancelled); manager %.2f us/tile; "
	       "hand-off %.2f us/tile\n",
	       workers, SESSIONS, (unsigned long long)L.lists, bulk_ly, n / sec, n,
	       (unsigned long long)st.merged, (unsigned long long)st.cancelled,
	       mtid ? (double)(m1 - m0) * 1e-3 / n : -1.0, (double)(p1 - p0) * 1e-3 / n);
	for (int k = 0; k < SESSIONS; k++)
		sched_req_destroy(L.req[k]);
	sched_req_destroy(bulk);
	rig_stop(&g);
	xmutex_destroy(&cnt.mu);
	xcond_destroy(&cnt.cv);
}

static int cmp_u64(const void *a, const void *b)
{
	uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
	return x < y ? -1 : x > y;
}

/* Want → callback for a tile already in the cache, one want list at a time. */
static void cached_latency(int rounds)
{
	struct planet p = { .tile_size = 256, .max_level = 12 };
	struct node n;
	node_setup(&n, &p, 0x777);
	struct cache *c = cache_create(0);
	struct sched_desc d = { .cache = c, .workers = 1 };
	struct sched *s = sched_create(&d);
	struct tile_key k = { .node = n.hash, .x = 3, .y = 2, .lx = 4, .ly = 3 };
	struct tile *t = tile_create(&k, PIX_HEIGHT, 256);
	memset(t->data, 0, t->nbytes);
	cache_insert(c, t);
	tile_unref(t);
	struct want w = { .node = &n, .key = k, .cls = SCHED_VISIBLE };
	struct counter cnt = { .target = 0 };
	xmutex_init(&cnt.mu);
	xcond_init(&cnt.cv);
	struct sched_req *r = sched_req_create(s, on_ready, &cnt);
	uint64_t *lat = malloc((size_t)rounds * sizeof *lat);
	if (!lat || !s || !c) {
		fprintf(stderr, "bench_sched: out of memory\n");
		exit(1);
	}
	for (int i = 0; i < rounds; i++) {
		xmutex_lock(&cnt.mu);
		cnt.target++;
		xmutex_unlock(&cnt.mu);
		uint64_t t0 = clock_now_ns();
		if (sched_req_want(r, &w, 1) != 0) {
			fprintf(stderr, "bench_sched: want refused\n");
			exit(1);
		}
		wait_count(&cnt);
		lat[i] = cnt.t_ready - t0;
	}
	qsort(lat, (size_t)rounds, sizeof *lat, cmp_u64);
	printf("sched/cached want->callback: p50 %.1f us\n", (double)lat[rounds / 2] * 1e-3);
	printf("sched/cached want->callback: p99 %.1f us\n", (double)lat[rounds * 99 / 100] * 1e-3);
	sched_req_destroy(r);
	sched_destroy(s);
	cache_destroy(c);
	xmutex_destroy(&cnt.mu);
	xcond_destroy(&cnt.cv);
	free(lat);
}

static double median3(double a, double b, double c)
{
	if (a > b) {
		double t = a;
		a = b;
		b = t;
	}
	return c < a ? a : c > b ? b : c;
}

/* Issue 20's goals beside the medians of three runs of its ceiling load (a near-free node, 16
 * workers), each run's figure listed: the machine is shared, one run says little. */
static void goals(const struct run r[3])
{
	double tps[3], mgr[3], ho[3];
	for (int k = 0; k < 3; k++) {
		tps[k] = (double)r[k].tiles / r[k].sec;
		mgr[k] = r[k].mgr_us;
		ho[k] = r[k].handoff_us;
	}
	double t = median3(tps[0], tps[1], tps[2]), m = median3(mgr[0], mgr[1], mgr[2]),
	       h = median3(ho[0], ho[1], ho[2]);
	printf("sched/goal tiles/s 16 workers: %.0f (median of 3: %.0f, %.0f, %.0f) vs 300000 "
	       "goal: %.2f×\n",
	       t, tps[0], tps[1], tps[2], t / 300000.0);
	printf("sched/goal serial µs/tile (manager CPU) 16 workers: %.2f (median of 3: %.2f, %.2f, "
	       "%.2f) vs the issue's baseline 31–35 µs (recorded in docs/ARCHITECTURE.md): %.0f× "
	       "less\n",
	       m, mgr[0], mgr[1], mgr[2], m > 0 ? 33.0 / m : 0.0);
	printf("sched/goal hand-off µs/tile 16 workers: %.2f (median of 3: %.2f, %.2f, %.2f) vs "
	       "10 µs goal (baseline 40–50): %.2f of the goal\n",
	       h, ho[0], ho[1], ho[2], h / 10.0);
	/* Worker time per node-tile of real synthesis: issue 20 measured ~750 us. */
	project(m, 750.0);
	double f = m / (m + 750.0), eff = 1.0 / (f + (1.0 - f) / 64) / 64;
	printf("sched/goal projected efficiency at 64 cores (750 µs nodes, %.2f µs serial): "
	       "%.1f %% vs 90 %% goal\n",
	       m, 100.0 * eff);
}

/* No argument: every figure. "ceiling": issue 20's three runs and the goal lines only;
 * "daemon": the daemon-like load only; "cached": the cached latency only (for profiling or
 * comparing one part). */
int main(int argc, char **argv)
{
	const char *only = argc > 1 ? argv[1] : NULL;
	struct run o, r3[3];
	if (only && strcmp(only, "daemon") == 0) {
		daemon_like(16, 7);
		return 0;
	}
	if (only && strcmp(only, "cached") == 0) {
		cached_latency(5000);
		return 0;
	}
	if (!only) {
		o = throughput(256, 1, 7, &t_cheap);
		print_run("cheap", 256, 1, &o);
		o = throughput(256, 2, 7, &t_cheap);
		print_run("cheap", 256, 2, &o);
		o = throughput(16, 1, 7, &t_cheap);
		print_run("cheap", 16, 1, &o);
		o = throughput(16, 2, 7, &t_cheap);
		print_run("cheap", 16, 2, &o);
	}
	/* Issue 20's ceiling: a near-free node, 16 workers; the median of three (load). */
	for (int k = 0; k < 3; k++) {
		r3[k] = throughput(16, 16, 8, &t_cheap);
		print_run("cheap", 16, 16, &r3[k]);
	}
	goals(r3);
	if (only)
		return 0;
	spin_ns = 1000;
	o = throughput(16, 16, 8, &t_spin);
	print_run("1us-node", 16, 16, &o);
	daemon_like(16, 7);
	cached_latency(5000);
	return 0;
}
