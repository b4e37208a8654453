/* xthread — checked pthread mutexes and condition variables. A failing lock, unlock, wait or
 * signal is a programmer error (EINVAL, EDEADLK, EPERM: a destroyed or unowned mutex), so,
 * like the xalloc family, it aborts with a message naming the call and the error instead of
 * going on unlocked. Condition variables wait on CLOCK_MONOTONIC (clock.h), so deadlines do
 * not move with the wall clock. Thread-safe as pthreads are. */
#ifndef CLIPMAP_XTHREAD_H
#define CLIPMAP_XTHREAD_H
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>

void xmutex_init(pthread_mutex_t *mu);
void xmutex_destroy(pthread_mutex_t *mu);
void xmutex_lock(pthread_mutex_t *mu);
void xmutex_unlock(pthread_mutex_t *mu);
/* A condition variable on CLOCK_MONOTONIC. */
void xcond_init(pthread_cond_t *cv);
void xcond_destroy(pthread_cond_t *cv);
void xcond_wait(pthread_cond_t *cv, pthread_mutex_t *mu);
/* Waits until signalled or until the monotonic time deadline_ns (clock_now_ns). Returns false
 * when the deadline passed. */
bool xcond_wait_until(pthread_cond_t *cv, pthread_mutex_t *mu, uint64_t deadline_ns);
void xcond_signal(pthread_cond_t *cv);
void xcond_broadcast(pthread_cond_t *cv);
/* Starts a thread; unlike the calls above, running out of threads is a runtime condition:
 * returns 0 or -errno (-EAGAIN). */
int xthread_create(pthread_t *t, void *(*fn)(void *), void *arg);
/* Joins t (a failure is a programmer error: aborts). */
void xthread_join(pthread_t t);
/* Puts the calling thread under SCHED_BATCH, its niceness kept: a thread woken by another
 * (a worker, the scheduler's manager, an encoder, a writer, woken by the event loop) then
 * does not preempt it at the wake-up, so the loop finishes its iteration instead of waiting
 * for a core. Any user may ask it. Returns 0 or -errno. */
int xthread_batch(const char *name);

#endif
