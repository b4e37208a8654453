/* linkest — see linkest.h. <linux/tcp.h> rather than <netinet/tcp.h>: glibc's struct tcp_info
 * stops before the delivery rate. */
#include "linkest.h"

#include <errno.h>
#include <string.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <linux/tcp.h>

#include "common/log.h"

static void set_lowat(struct linkest *le, uint32_t v)
{
	if (v == le->lowat)
		return;
	if (setsockopt(le->fd, IPPROTO_TCP, TCP_NOTSENT_LOWAT, &v, sizeof v)) {
		log_msg(LOG_DEBUG, "TCP_NOTSENT_LOWAT: %s", strerror(errno));
		return;
	}
	le->lowat = v;
}

uint32_t linkest_cap(uint64_t rate, uint32_t min_rtt_us)
{
	if (!rate || rate >= LINKEST_CAP_BELOW || !min_rtt_us || min_rtt_us > LINKEST_CAP_RTT_MAX)
		return 0;
	/* < 500 kB/s × (10 s + 40 ms): fits */
	uint64_t b = rate * ((uint64_t)min_rtt_us + LINKEST_CAP_MS * 1000u) / 1000000u;
	return b < LINKEST_CAP_MIN ? LINKEST_CAP_MIN : (uint32_t)b;
}

static bool capped(const struct linkest *le)
{
	return le->sndbuf && le->sndbuf != LINKEST_UNCAPPED;
}

/* Gives the buffer back to the kernel's autotuning: SO_BUF_LOCK 0 (Linux 5.14); before that
 * kernel, the most SO_SNDBUF gives (LINKEST_UNCAPPED, within net.core.wmem_max), locked. */
static void uncap(struct linkest *le)
{
#ifdef SO_BUF_LOCK
	int zero = 0;
	if (setsockopt(le->fd, SOL_SOCKET, SO_BUF_LOCK, &zero, sizeof zero) == 0) {
		le->sndbuf = 0;
		return;
	}
	log_msg(LOG_DEBUG, "SO_BUF_LOCK: %s", strerror(errno));
#endif
	int v = (int)LINKEST_UNCAPPED;
	if (setsockopt(le->fd, SOL_SOCKET, SO_SNDBUF, &v, sizeof v))
		log_msg(LOG_DEBUG, "SO_SNDBUF: %s", strerror(errno));
	else
		le->sndbuf = LINKEST_UNCAPPED;
}

/* Only on a link measured once while it was the limit (a sample not application-limited: an
 * idle session's estimate says nothing of the link). Rises of a sixteenth are followed (a
 * capped sender's samples can beat the estimate only by the cap's headroom, so a long round
 * trip must not be held below its rate by a coarse rule), falls of a quarter; a capped link
 * is let go at 1.25 × LINKEST_CAP_BELOW (an estimate near the threshold does not flap). */
void linkest_set_cap(struct linkest *le)
{
	if (!le->measured)
		return;
	uint64_t r = le->rate;
	if (capped(le) && r >= LINKEST_CAP_BELOW && r < (uint64_t)LINKEST_CAP_BELOW * 5 / 4)
		r = LINKEST_CAP_BELOW - 1;
	uint32_t v = linkest_cap(r, le->min_rtt_us);
	if (!v) {
		if (capped(le))
			uncap(le);
		return;
	}
	uint64_t was = capped(le) ? le->sndbuf : 0;
	if (was && (uint64_t)v * 16 <= was * 17 && (uint64_t)v * 5 >= was * 4)
		return;
	int iv = (int)v;
	if (setsockopt(le->fd, SOL_SOCKET, SO_SNDBUF, &iv, sizeof iv)) {
		log_msg(LOG_DEBUG, "SO_SNDBUF: %s", strerror(errno));
		return;
	}
	le->sndbuf = v;
}

void linkest_init(struct linkest *le, int fd, bool tcp, bool lowat, bool bbr, uint64_t now_ns)
{
	*le = (struct linkest){ .fd = fd, .tcp = tcp, .win_start = now_ns };
	if (tcp && bbr && setsockopt(fd, IPPROTO_TCP, TCP_CONGESTION, "bbr", 3))
		log_msg(LOG_DEBUG, "TCP_CONGESTION bbr: %s (the system's default stays)",
			strerror(errno));
	if (tcp) {
		if (lowat)
			set_lowat(le, LINKEST_LOWAT_MIN);
		linkest_sample(le, now_ns, true);
	}
}

/* The filter: a sample into this window's maximum; the estimate is the larger of the two
 * windows' maxima. Application-limited samples only count when they raise the estimate. */
static void add_rate(struct linkest *le, uint64_t now_ns, uint64_t r, bool app_limited)
{
	if (now_ns - le->win_start >= LINKEST_WINDOW_NS) {
		le->win_max[1] = now_ns - le->win_start >= 2 * LINKEST_WINDOW_NS ? 0 : le->win_max[0];
		le->win_max[0] = 0;
		le->win_start = now_ns;
	}
	if (r && (!app_limited || r > le->rate))
		le->win_max[0] = r > le->win_max[0] ? r : le->win_max[0];
	uint64_t est = le->win_max[0] > le->win_max[1] ? le->win_max[0] : le->win_max[1];
	/* an idle link (every sample application-limited) keeps what it had */
	if (est)
		le->rate = est;
}

void linkest_sample(struct linkest *le, uint64_t now_ns, bool force)
{
	if (!le->tcp || (!force && le->last_ns && now_ns - le->last_ns < LINKEST_SAMPLE_NS))
		return;
	struct tcp_info ti;
	socklen_t len = sizeof ti;
	memset(&ti, 0, sizeof ti);
	if (getsockopt(le->fd, IPPROTO_TCP, TCP_INFO, &ti, &len))
		return;
	le->last_ns = now_ns;
	le->rtt_us = ti.tcpi_rtt;
	/* ~0: no RTT sample yet */
	le->min_rtt_us = ti.tcpi_min_rtt && ti.tcpi_min_rtt != ~0u ? ti.tcpi_min_rtt : ti.tcpi_rtt;
	le->notsent = ti.tcpi_notsent_bytes;
	le->unacked = (uint64_t)ti.tcpi_unacked * ti.tcpi_snd_mss;
	bool grew = ti.tcpi_bytes_acked > le->acked;
	le->acked = ti.tcpi_bytes_acked;
	/* a delivery-rate sample is new only when more was acknowledged */
	if (grew) {
		add_rate(le, now_ns, ti.tcpi_delivery_rate, ti.tcpi_delivery_rate_app_limited);
		le->measured |= ti.tcpi_delivery_rate && !ti.tcpi_delivery_rate_app_limited;
	} else {
		add_rate(le, now_ns, 0, true);
	}
	uint64_t lw = le->rate * LINKEST_LOWAT_MS / 1000;
	lw = lw < LINKEST_LOWAT_MIN ? LINKEST_LOWAT_MIN : lw > LINKEST_LOWAT_MAX ? LINKEST_LOWAT_MAX : lw;
	/* only moves of a quarter or more: a setsockopt per sample is for nothing */
	if (le->lowat && (lw * 4 > (uint64_t)le->lowat * 5 || lw * 5 < (uint64_t)le->lowat * 4))
		set_lowat(le, (uint32_t)lw);
	if (le->lowat) /* the send window is on (send_queue_ms > 0) */
		linkest_set_cap(le);
}

uint64_t linkest_window(const struct linkest *le, uint32_t queue_ms, uint64_t cap)
{
	if (!le->tcp || !queue_ms)
		return cap;
	uint64_t w = le->rate / 1000 * queue_ms;
	w = w < LINKEST_FLOOR ? LINKEST_FLOOR : w;
	return w > cap ? cap : w;
}

double linkest_delay_ms(const struct linkest *le, uint64_t bytes)
{
	return le->tcp && le->rate ? (double)bytes * 1000.0 / (double)le->rate : 0.0;
}

uint32_t linkest_part(const struct linkest *le)
{
	if (!le->tcp)
		return 0;
	if (!le->rate)
		return LINKEST_PART_MAX;
	uint64_t b = le->rate * LINKEST_PART_MS / 1000u;
	return b < LINKEST_PART_MIN ? LINKEST_PART_MIN : b > LINKEST_PART_MAX ? LINKEST_PART_MAX
									    : (uint32_t)b;
}
