/* loopstat — see loopstat.h. */
#include "loopstat.h"

static const unsigned bounds[LOOPSTAT_NB - 1] = LOOPSTAT_BOUNDS;

unsigned loopstat_bound_ms(int i)
{
	return i >= 0 && i < LOOPSTAT_NB - 1 ? bounds[i] : 0;
}

void loopstat_add(struct loopstat *ls, uint64_t ns)
{
	int i = 0;
	while (i < LOOPSTAT_NB - 1 && ns > (uint64_t)bounds[i] * 1000000u)
		i++;
	ls->b[i]++;
	ls->n++;
	if (ns > ls->max_ns)
		ls->max_ns = ns;
}

void loopstat_why(struct loopstat *ls, uint64_t ns, uint64_t cpu_ns, uint64_t voluntary)
{
	if (cpu_ns > ls->cpu_max_ns)
		ls->cpu_max_ns = cpu_ns;
	const uint64_t slow = (uint64_t)LOOPSTAT_SLOW_MS * 1000000u;
	if (ns <= slow)
		return;
	if (cpu_ns > slow)
		ls->slow_work++;
	else if (voluntary)
		ls->slow_blocked++;
	else
		ls->slow_preempted++;
}

double loopstat_quantile_ms(const struct loopstat *ls, double p)
{
	if (!ls->n)
		return 0.0;
	double max_ms = (double)ls->max_ns * 1e-6;
	uint64_t need = (uint64_t)(p * (double)ls->n + 0.999999);
	if (need < 1)
		need = 1;
	uint64_t seen = 0;
	for (int i = 0; i < LOOPSTAT_NB - 1; i++) {
		seen += ls->b[i];
		if (seen >= need)
			return (double)bounds[i] < max_ms ? (double)bounds[i] : max_ms;
	}
	return max_ms;
}

uint64_t loopstat_over(const struct loopstat *ls, unsigned ms)
{
	uint64_t n = 0;
	for (int i = LOOPSTAT_NB - 1; i > 0 && bounds[i - 1] >= ms; i--)
		n += ls->b[i];
	return n;
}
