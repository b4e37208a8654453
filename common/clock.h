/* clock — the one monotonic clock every part measures time with (deadlines, latencies, ages).
 * Thread-safe, no state. */
#ifndef CLIPMAP_CLOCK_H
#define CLIPMAP_CLOCK_H
#include <stdint.h>
#include <time.h>

/* CLOCK_MONOTONIC in nanoseconds. */
uint64_t clock_now_ns(void);
/* CLOCK_MONOTONIC in seconds, and in milliseconds. */
double clock_now_s(void);
double clock_now_ms(void);
/* The timespec of a CLOCK_MONOTONIC time given in nanoseconds (for timed waits on a
 * condition variable made by xcond_init, which waits on that clock). */
struct timespec clock_ts_of_ns(uint64_t ns);

#endif
