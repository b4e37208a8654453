/* xthread — see xthread.h. */
#include "xthread.h"

#include <errno.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"

static void check(int rc, const char *call)
{
	if (rc == 0)
		return;
	fprintf(stderr, "clipmap: %s failed: %s\n", call, strerror(rc));
	abort();
}

void xmutex_init(pthread_mutex_t *mu)
{
	check(pthread_mutex_init(mu, NULL), "pthread_mutex_init");
}

void xmutex_destroy(pthread_mutex_t *mu)
{
	check(pthread_mutex_destroy(mu), "pthread_mutex_destroy");
}

void xmutex_lock(pthread_mutex_t *mu)
{
	check(pthread_mutex_lock(mu), "pthread_mutex_lock");
}

void xmutex_unlock(pthread_mutex_t *mu)
{
	check(pthread_mutex_unlock(mu), "pthread_mutex_unlock");
}

void xcond_init(pthread_cond_t *cv)
{
	pthread_condattr_t a;
	check(pthread_condattr_init(&a), "pthread_condattr_init");
	check(pthread_condattr_setclock(&a, CLOCK_MONOTONIC), "pthread_condattr_setclock");
	check(pthread_cond_init(cv, &a), "pthread_cond_init");
	check(pthread_condattr_destroy(&a), "pthread_condattr_destroy");
}

void xcond_destroy(pthread_cond_t *cv)
{
	check(pthread_cond_destroy(cv), "pthread_cond_destroy");
}

void xcond_wait(pthread_cond_t *cv, pthread_mutex_t *mu)
{
	check(pthread_cond_wait(cv, mu), "pthread_cond_wait");
}

bool xcond_wait_until(pthread_cond_t *cv, pthread_mutex_t *mu, uint64_t deadline_ns)
{
	struct timespec ts = clock_ts_of_ns(deadline_ns);
	int rc = pthread_cond_timedwait(cv, mu, &ts);
	if (rc == ETIMEDOUT)
		return false;
	check(rc, "pthread_cond_timedwait");
	return true;
}

void xcond_signal(pthread_cond_t *cv)
{
	check(pthread_cond_signal(cv), "pthread_cond_signal");
}

void xcond_broadcast(pthread_cond_t *cv)
{
	check(pthread_cond_broadcast(cv), "pthread_cond_broadcast");
}

int xthread_create(pthread_t *t, void *(*fn)(void *), void *arg)
{
	int rc = pthread_create(t, NULL, fn, arg);
	return rc ? -rc : 0;
}

void xthread_join(pthread_t t)
{
	check(pthread_join(t, NULL), "pthread_join");
}

int xthread_batch(const char *name)
{
	if (name)
		pthread_setname_np(pthread_self(), name); /* for top -H, perf, gdb */
	struct sched_param p = { .sched_priority = 0 };
	int rc = pthread_setschedparam(pthread_self(), SCHED_BATCH, &p);
	return rc ? -rc : 0;
}
