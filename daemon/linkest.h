/* linkest — one session's link, measured: throughput and round-trip time from the kernel's
 * TCP_INFO (tcpi_delivery_rate, tcpi_rtt, tcpi_min_rtt, tcpi_bytes_acked) on TCP sockets, and
 * the send window sized from them: how many bytes the session may keep encoded but not yet
 * handed to the kernel (send_queue_ms of the measured rate, at least LINKEST_FLOOR, at most
 * max_pending), and the TCP_NOTSENT_LOWAT the kernel keeps (a few milliseconds of the rate),
 * so that a new want-set finds little already committed. A Unix socket is not measured: it is
 * treated as fast (the window is max_pending, as before).
 *
 * The rate is a windowed maximum of the delivery-rate samples over the last two windows of
 * LINKEST_WINDOW_NS (BBR's bandwidth filter, coarser): samples the kernel marks
 * application-limited count only when they raise it, so an idle session keeps its figure.
 *
 * Threads: the event loop's. Ownership: borrows the fd.
 */
#ifndef CLIPMAP_LINKEST_H
#define CLIPMAP_LINKEST_H
#include <stdbool.h>
#include <stdint.h>

#define LINKEST_FLOOR (32u << 10)		/* bytes: the send window's least size */
#define LINKEST_WINDOW_NS 1000000000ull	/* the bandwidth filter's window */
#define LINKEST_SAMPLE_NS 5000000ull	/* TCP_INFO at most this often */
#define LINKEST_LOWAT_MIN (2u << 10)	/* TCP_NOTSENT_LOWAT's bounds */
#define LINKEST_LOWAT_MAX (1u << 20)
#define LINKEST_LOWAT_MS 10u		/* TCP_NOTSENT_LOWAT: this much of the rate */
#define LINKEST_PART_MS 20u		/* a tile in parts (TILE_PART): this much of the rate each */
#define LINKEST_PART_MIN (2u << 10)	/* and these bounds (the most before a rate is measured) */
#define LINKEST_PART_MAX (64u << 10)
/* On slow links the kernel's send buffer (SO_SNDBUF) is held to the bandwidth-delay product
 * and LINKEST_CAP_MS more: BBR's floors count packets (four in its least cwnd, three TSO
 * goals of quantisation budget), so below a few Mbit/s they let it keep 150 ms and more of
 * the rate in flight, and a new want-set waits behind it. Measured at 1 Mbit/s, 40 ms
 * (bench_link): stale bytes after a jump 22 → 12-15 KB with lossy tiles, 14-17 → 12 KB with
 * lossless ones. The kernel doubles what it is asked and counts each packet's overhead in
 * it, so what it holds in flight is about 1.1-1.4 × rate × (least RTT + LINKEST_CAP_MS).
 * Above LINKEST_CAP_BELOW the kernel's own buffering stays: there BBR holds about one BDP
 * itself, and a locked buffer made it hold more (20 Mbit/s: 91-104 KB in flight → 150-160).
 * A capped sender's samples can still beat the estimate by that 1.1-1.4 × (1 + CAP_MS /
 * least RTT) — over 1.1 × at any round trip up to LINKEST_CAP_RTT_MAX — so a link that got
 * faster is found; rises are followed in sixteenths for that. */
#define LINKEST_CAP_MS 40u
#define LINKEST_CAP_BELOW 500000u	/* bytes/s (4 Mbit/s); let go at 1.25 × this */
#define LINKEST_CAP_MIN (8u << 10)	/* the least send buffer asked for */
#define LINKEST_CAP_RTT_MAX 10000000u	/* µs: a least RTT beyond this is not believed */
#define LINKEST_UNCAPPED (4u << 20)	/* asked for where SO_BUF_LOCK cannot let go */

struct linkest {
	int fd;
	bool tcp;	    /* measured; false: a Unix socket, treated as fast */
	uint64_t last_ns;   /* the last sample */
	uint64_t rate;	    /* bytes/s: the estimate (0: none yet) */
	uint64_t win_max[2]; /* the filter: this window's and the last one's maximum */
	uint64_t win_start;
	uint32_t rtt_us, min_rtt_us; /* smoothed and least RTT (0: none yet) */
	uint64_t acked;	     /* tcpi_bytes_acked at the last sample */
	uint64_t notsent;    /* tcpi_notsent_bytes: in the kernel, not yet sent */
	uint64_t unacked;    /* bytes sent, not yet acknowledged (tcpi_unacked × mss) */
	uint32_t lowat;	     /* TCP_NOTSENT_LOWAT set (0: not set) */
	uint32_t sndbuf;     /* SO_SNDBUF asked for by the slow-link cap (0: the kernel's own;
			      * LINKEST_UNCAPPED: let go where SO_BUF_LOCK is not known) */
	bool measured;	     /* a delivery-rate sample not application-limited was seen */
};

/* Starts measuring fd (borrowed); tcp false for a Unix socket. On TCP with lowat true it sets
 * the first TCP_NOTSENT_LOWAT (LINKEST_LOWAT_MIN) and keeps it sized from the rate; false
 * leaves the kernel's default (send_queue_ms 0). bbr: asks for BBR congestion control
 * (TCP_CONGESTION), which keeps the bottleneck's queue near one bandwidth-delay product where
 * loss-based CUBIC fills it (seconds of stale bytes in flight on a bloated link); where the
 * kernel has no BBR or does not allow it, the system's default stays (logged at debug). */
void linkest_init(struct linkest *le, int fd, bool tcp, bool lowat, bool bbr, uint64_t now_ns);
/* Takes a TCP_INFO sample unless one is younger than LINKEST_SAMPLE_NS (force: take it
 * anyway), updates the rate and RTT and, when the rate moved, TCP_NOTSENT_LOWAT and (where
 * the send window is on) the slow-link cap on SO_SNDBUF. */
void linkest_sample(struct linkest *le, uint64_t now_ns, bool force);
/* The send window in bytes: queue_ms of the rate, within [LINKEST_FLOOR, cap]; cap on a Unix
 * socket. queue_ms 0: cap (the window is not sized from the link). */
uint64_t linkest_window(const struct linkest *le, uint32_t queue_ms, uint64_t cap);
/* The payload bytes of one TILE_PART to a peer that reassembles them: LINKEST_PART_MS of the
 * rate within [LINKEST_PART_MIN, LINKEST_PART_MAX], the most before a rate is measured; 0
 * (whole tiles) on a Unix socket. A recall stops a tile after its part in flight, so this is
 * what a new want-set may wait behind. */
uint32_t linkest_part(const struct linkest *le);
/* The send buffer the slow-link cap asks for at this rate and least RTT (0: none, the
 * kernel's own: no rate yet, or rate >= LINKEST_CAP_BELOW). */
uint32_t linkest_cap(uint64_t rate, uint32_t min_rtt_us);
/* Asks the kernel for that cap at le's rate and least RTT once the link was measured
 * (linkest_sample does, where the send window is on); a capped socket whose rate passed
 * 1.25 × LINKEST_CAP_BELOW is given back to the kernel's autotuning. */
void linkest_set_cap(struct linkest *le);
/* How long `bytes` take at the measured rate, in milliseconds (0 when not measured). */
double linkest_delay_ms(const struct linkest *le, uint64_t bytes);

#endif
