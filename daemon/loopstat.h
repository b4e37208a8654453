/* loopstat — how long the event loop's iterations took: a fixed histogram of the time from
 * epoll_wait's return to the end of the iteration (the work, not the wait), its maximum and
 * count, and the 99th percentile read from the buckets. What STATS exports as loop.* so that
 * "the loop never blocks longer than 50 ms" can be checked on a running daemon.
 *
 * Threads: one owner thread (the loop). Pure: no clock of its own.
 */
#ifndef CLIPMAP_LOOPSTAT_H
#define CLIPMAP_LOOPSTAT_H
#include <stdint.h>

/* Upper bounds of the buckets in ms; one more bucket holds everything above the last. */
#define LOOPSTAT_BOUNDS { 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000 }
#define LOOPSTAT_NB 13

struct loopstat {
	uint64_t n;	 /* iterations */
	uint64_t max_ns; /* the longest */
	uint64_t b[LOOPSTAT_NB];
	/* the iterations over LOOPSTAT_SLOW_MS, by why: the loop's own CPU passed it (work);
	 * else it waited on something (a voluntary context switch inside the iteration: a lock,
	 * a blocking call); else it was only preempted (runnable, the cores busy elsewhere) */
	uint64_t slow_work, slow_blocked, slow_preempted;
	uint64_t cpu_max_ns; /* the most CPU one iteration used */
};
#define LOOPSTAT_SLOW_MS 50

/* Counts one iteration that took ns. */
void loopstat_add(struct loopstat *ls, uint64_t ns);
/* What the thread's own CPU clock and context switches say about the same iteration: cpu_ns
 * used, voluntary switches during it (getrusage RUSAGE_THREAD). Call after loopstat_add. */
void loopstat_why(struct loopstat *ls, uint64_t ns, uint64_t cpu_ns, uint64_t voluntary);
/* The upper bound (ms) of the bucket that holds the p-th quantile (0 < p ≤ 1) of the counted
 * iterations, the maximum itself when that is the open bucket or smaller; 0 with none. */
double loopstat_quantile_ms(const struct loopstat *ls, double p);
/* Bucket i's upper bound in ms (0 for the open bucket, i = LOOPSTAT_NB - 1). */
unsigned loopstat_bound_ms(int i);
/* How many iterations took longer than ms (ms one of the bounds). */
uint64_t loopstat_over(const struct loopstat *ls, unsigned ms);

#endif
