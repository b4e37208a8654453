/* shaped_link — see shaped_link.h. The namespaces and links are made with ip(8) (its output
 * into a buffer, shown when it fails); the names carry the test's pid so that runs side by
 * side do not meet, and stale ones (their pid gone) are removed at setup. The relay is a
 * forked process in the middle namespace: two AF_PACKET sockets, a queue per direction. */
#include "shaped_link.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <net/if.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <arpa/inet.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <linux/virtio_net.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/errbuf.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "support/daemon_env.h"

#define NS_PREFIX "clipmap-link-"
#define NETNS_DIR "/var/run/netns"

static struct shaped_link *live; /* the one removed at exit or on a signal */
static void (*live_fini)(void);	 /* the caller's cleanup, first */

void shaped_link_on_fini(void (*fn)(void))
{
	live_fini = fn;
}

/* Runs a command line (argv built from fmt, split at spaces); its output into out. Returns
 * its exit status (127: not found). */
static int __attribute__((format(printf, 3, 4))) cmd(char *out, size_t n, const char *fmt, ...)
{
	char line[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(line, sizeof line, fmt, ap);
	va_end(ap);
	char *argv[32];
	int argc = 0;
	for (char *save, *t = strtok_r(line, " ", &save); t && argc < 31;
	     t = strtok_r(NULL, " ", &save))
		argv[argc++] = t;
	argv[argc] = NULL;
	char sink[1024];
	if (!out) {
		out = sink;
		n = sizeof sink;
	}
	return daemon_env_run(argv, out, n);
}

static void stop_relay(struct shaped_link *sl)
{
	if (sl->relay > 0) {
		kill(sl->relay, SIGKILL);
		waitpid(sl->relay, NULL, 0);
	}
	sl->relay = 0;
}

void shaped_link_fini(struct shaped_link *sl)
{
	if (!sl || !sl->ns[0])
		return;
	stop_relay(sl);
	/* the veth pairs go with their ends in the namespaces */
	cmd(NULL, 0, "ip netns del %s", sl->ns);
	cmd(NULL, 0, "ip netns del %s", sl->mid);
	cmd(NULL, 0, "ip link del %s", sl->dev); /* in case the pair outlived them */
	sl->ns[0] = 0;
	sl->up = false;
	if (live == sl)
		live = NULL;
}

static void at_exit(void)
{
	if (live && live_fini)
		live_fini();
	shaped_link_fini(live);
}

static void on_signal(int sig)
{
	if (live && live_fini)
		live_fini();
	shaped_link_fini(live);
	signal(sig, SIG_DFL);
	raise(sig);
}

/* Removes namespaces of earlier runs whose process is gone (a SIGKILL leaves them). */
static void sweep_stale(void)
{
	DIR *d = opendir(NETNS_DIR);
	if (!d)
		return;
	struct dirent *de;
	while ((de = readdir(d))) {
		if (strncmp(de->d_name, NS_PREFIX, strlen(NS_PREFIX)) != 0)
			continue;
		long pid = strtol(de->d_name + strlen(NS_PREFIX), NULL, 10);
		if (pid > 0 && kill((pid_t)pid, 0) != 0 && errno == ESRCH) {
			cmd(NULL, 0, "ip netns del %s", de->d_name);
			cmd(NULL, 0, "ip link del cml%lds", pid % 10000000);
		}
	}
	closedir(d);
}

int shaped_link_init(struct shaped_link *sl, char why[256])
{
	*sl = (struct shaped_link){ 0 };
	if (geteuid() != 0) {
		err_set(why, "network namespaces need root (running as uid %ld)", (long)geteuid());
		return -ENOTSUP;
	}
	char out[1024];
	if (cmd(out, sizeof out, "ip -V") != 0) {
		err_set(why, "ip(8) not found (apt-get install iproute2)");
		return -ENOTSUP;
	}
	sweep_stale();
	long pid = (long)getpid(), p7 = pid % 10000000;
	unsigned base = (unsigned)(pid % 16384) * 4; /* a /30 of 10.211.0.0/16 per pid */
	snprintf(sl->ns, sizeof sl->ns, NS_PREFIX "%ld", pid);
	snprintf(sl->mid, sizeof sl->mid, NS_PREFIX "%ld-relay", pid);
	snprintf(sl->dev, sizeof sl->dev, "cml%lds", p7);
	snprintf(sl->peer, sizeof sl->peer, "cml%ldc", p7);
	snprintf(sl->addr, sizeof sl->addr, "10.211.%u.%u", base >> 8, (base & 255) + 1);
	snprintf(sl->peer_addr, sizeof sl->peer_addr, "10.211.%u.%u", base >> 8, (base & 255) + 2);
	if (cmd(out, sizeof out, "ip netns add %s", sl->ns) != 0) {
		err_set(why, "ip netns add refused (no network namespaces here): %.180s", out);
		sl->ns[0] = 0;
		return -ENOTSUP;
	}
	live = sl;
	atexit(at_exit);
	signal(SIGINT, on_signal);
	signal(SIGTERM, on_signal);
	signal(SIGHUP, on_signal);
	signal(SIGPIPE, on_signal); /* output into a pipe whose reader left (| head) */
	int rc = 0;
	if ((rc = cmd(out, sizeof out, "ip netns add %s", sl->mid)) ||
	    (rc = cmd(out, sizeof out, "ip link add %s gso_max_segs 1 type veth peer name cml%lda "
		      "netns %s", sl->dev, p7, sl->mid)) ||
	    (rc = cmd(out, sizeof out, "ip -n %s link add cml%ldb type veth peer name %s netns %s",
		      sl->mid, p7, sl->peer, sl->ns)) ||
	    (rc = cmd(out, sizeof out, "ip addr add %s/30 dev %s", sl->addr, sl->dev)) ||
	    (rc = cmd(out, sizeof out, "ip link set %s up", sl->dev)) ||
	    (rc = cmd(out, sizeof out, "ip -n %s link set cml%lda up promisc on", sl->mid, p7)) ||
	    (rc = cmd(out, sizeof out, "ip -n %s link set cml%ldb up promisc on", sl->mid, p7)) ||
	    (rc = cmd(out, sizeof out, "ip -n %s link set %s gso_max_segs 1", sl->ns, sl->peer)) ||
	    (rc = cmd(out, sizeof out, "ip -n %s addr add %s/30 dev %s", sl->ns, sl->peer_addr,
		      sl->peer)) ||
	    (rc = cmd(out, sizeof out, "ip -n %s link set %s up", sl->ns, sl->peer)) ||
	    (rc = cmd(out, sizeof out, "ip -n %s link set lo up", sl->ns))) {
		err_set(why, "setting up the veth links failed: %.200s", out);
		shaped_link_fini(sl);
		return -ENOTSUP;
	}
	sl->up = true;
	return 0;
}

/* ---- the relay -------------------------------------------------------------------------- */

struct frame {
	uint64_t due; /* when it leaves the relay */
	uint32_t len; /* bytes, virtio-net header included */
	uint8_t *data;
};

struct fq {
	struct frame f[8192]; /* a ring */
	size_t head, n;
	uint64_t bytes, last_dep;
};

static int packet_socket(const char *ifname)
{
	int fd = socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, htons(ETH_P_ALL));
	int one = 1, buf = 8 << 20;
	struct sockaddr_ll sa = { .sll_family = AF_PACKET, .sll_protocol = htons(ETH_P_ALL),
				  .sll_ifindex = (int)if_nametoindex(ifname) };
	if (fd < 0 || !sa.sll_ifindex ||
	    setsockopt(fd, SOL_PACKET, PACKET_VNET_HDR, &one, sizeof one) ||
	    setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &buf, sizeof buf) ||
	    bind(fd, (struct sockaddr *)&sa, sizeof sa))
		return -1;
	return fd;
}

/* Reads what fd holds into q: shaped (rate, delay) or passed on at once. */
static void take(int fd, struct fq *q, uint64_t ns_per_byte, uint64_t delay_ns)
{
	for (;;) {
		uint8_t buf[70000];
		struct sockaddr_ll from;
		socklen_t fl = sizeof from;
		ssize_t n = recvfrom(fd, buf, sizeof buf, MSG_DONTWAIT, (struct sockaddr *)&from, &fl);
		if (n <= 0)
			return;
		if (from.sll_pkttype == PACKET_OUTGOING)
			continue; /* our own, sent out of this end */
		size_t wire = (size_t)n - sizeof(struct virtio_net_hdr);
		if (q->n == sizeof q->f / sizeof q->f[0] ||
		    (ns_per_byte && q->bytes + wire > SHAPED_QUEUE_BYTES))
			continue; /* tail drop */
		uint64_t now = clock_now_ns(), dep = now;
		if (ns_per_byte) {
			dep = (q->last_dep > now ? q->last_dep : now) + wire * ns_per_byte;
			q->last_dep = dep;
		}
		struct frame *f = &q->f[(q->head + q->n++) % (sizeof q->f / sizeof q->f[0])];
		*f = (struct frame){ .due = dep + delay_ns, .len = (uint32_t)n, .data = malloc((size_t)n) };
		memcpy(f->data, buf, (size_t)n);
		q->bytes += wire;
	}
}

/* Sends q's frames that are due out of fd; returns when the next is due (UINT64_MAX: none). */
static uint64_t give(int fd, struct fq *q)
{
	uint64_t now = clock_now_ns();
	while (q->n) {
		struct frame *f = &q->f[q->head];
		if (f->due > now)
			return f->due;
		if (send(fd, f->data, f->len, 0) < 0 && errno == EAGAIN)
			return now + 100000; /* the far end's queue is full: soon */
		q->bytes -= f->len - sizeof(struct virtio_net_hdr);
		free(f->data);
		q->head = (q->head + 1) % (sizeof q->f / sizeof q->f[0]);
		q->n--;
	}
	return UINT64_MAX;
}

static void __attribute__((noreturn)) relay_main(const struct shaped_link *sl, unsigned rate_kbit,
						  unsigned delay_ms)
{
	char path[128], a[16], b[16];
	snprintf(path, sizeof path, NETNS_DIR "/%s", sl->mid);
	int nsfd = open(path, O_RDONLY | O_CLOEXEC);
	if (nsfd < 0 || setns(nsfd, CLONE_NEWNET))
		_exit(2);
	/* the middle namespace's ends: dev's name with 'a' and 'b' for its 's' */
	snprintf(a, sizeof a, "%.*sa", (int)strlen(sl->dev) - 1, sl->dev);
	snprintf(b, sizeof b, "%.*sb", (int)strlen(sl->dev) - 1, sl->dev);
	int fa = packet_socket(a), fb = packet_socket(b);
	if (fa < 0 || fb < 0)
		_exit(3);
	static struct fq down, up; /* daemon to client (shaped), client to daemon */
	uint64_t npb = 8000000u / (rate_kbit ? rate_kbit : 1), delay = (uint64_t)delay_ms * 1000000u;
	for (;;) {
		uint64_t next = give(fb, &down), n2 = give(fa, &up);
		next = n2 < next ? n2 : next;
		struct pollfd pf[2] = { { .fd = fa, .events = POLLIN }, { .fd = fb, .events = POLLIN } };
		struct timespec ts, *tp = NULL;
		if (next != UINT64_MAX) {
			uint64_t now = clock_now_ns(), d = next > now ? next - now : 0;
			ts = (struct timespec){ .tv_sec = (time_t)(d / 1000000000u),
						.tv_nsec = (long)(d % 1000000000u) };
			tp = &ts;
		}
		if (ppoll(pf, 2, tp, NULL) < 0 && errno != EINTR)
			_exit(4);
		take(fa, &down, npb, delay);
		take(fb, &up, 0, 0);
	}
}

int shaped_link_shape(struct shaped_link *sl, unsigned rate_kbit, unsigned delay_ms,
		      char why[256])
{
	stop_relay(sl);
	fflush(NULL);
	pid_t p = fork();
	if (p < 0) {
		err_set(why, "fork: %s", strerror(errno));
		return -errno;
	}
	if (p == 0) {
		live = NULL; /* the parent removes the link, not this process */
		live_fini = NULL;
		signal(SIGINT, SIG_DFL);
		signal(SIGTERM, SIG_DFL);
		signal(SIGHUP, SIG_DFL);
		signal(SIGPIPE, SIG_DFL);
		relay_main(sl, rate_kbit, delay_ms);
	}
	sl->relay = p;
	/* it opens its sockets at once: one that cannot exits within a moment */
	nanosleep(&(struct timespec){ .tv_nsec = 100000000 }, NULL);
	int st = 0;
	if (waitpid(p, &st, WNOHANG) == p) {
		sl->relay = 0;
		err_set(why, "the link relay failed (exit %d): no AF_PACKET sockets here?",
			WIFEXITED(st) ? WEXITSTATUS(st) : -1);
		return -ENOTSUP;
	}
	return 0;
}

int shaped_link_connect(struct shaped_link *sl, int port)
{
	char path[128];
	snprintf(path, sizeof path, NETNS_DIR "/%s", sl->ns);
	int self = open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
	int there = open(path, O_RDONLY | O_CLOEXEC);
	int fd = -1, rc = 0;
	if (self < 0 || there < 0 || setns(there, CLONE_NEWNET)) {
		rc = -errno;
		goto out;
	}
	fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port) };
	inet_pton(AF_INET, sl->addr, &sa.sin_addr);
	if (fd < 0 || connect(fd, (struct sockaddr *)&sa, sizeof sa)) {
		rc = -errno;
		if (fd >= 0)
			close(fd);
		fd = -1;
	}
	if (setns(self, CLONE_NEWNET)) /* back: the daemon's namespace */
		abort();
out:
	if (self >= 0)
		close(self);
	if (there >= 0)
		close(there);
	return fd >= 0 ? fd : rc;
}

/* ---- the jump --------------------------------------------------------------------------- */

const char shaped_link_planet[] =
	"[planet]\nname = test\nbody = sphere\nradius = 1000000\ntile_size = 128\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = 3\noctaves = 3\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

int shaped_link_daemon_start(const struct shaped_link *sl, struct daemon_env *e, const char *tag,
			     const char *token, const char *const *extra, char why[256])
{
	char tcp[64];
	snprintf(tcp, sizeof tcp, "listen.tcp = %s:0", sl->addr);
	const char *set[16] = { tcp, "engine.workers = 2", "engine.cache_mb = 256",
				"session.max_rate = 1000", "log.level = info" };
	for (int i = 0, n = 5; extra && i < 8 && extra[i]; i++)
		set[n++] = extra[i];
	const struct daemon_env_conf conf = { .set = set, .token = token };
	why[0] = '\0';
	if (daemon_env_init(e, tag) ||
	    daemon_env_planet_text(e, "test.ini", shaped_link_planet, NULL) ||
	    daemon_env_start(e, &conf, why)) {
		if (!why[0])
			err_set(why, "cannot prepare the daemon's directory for %s", tag);
		daemon_env_fini(e);
		return -1;
	}
	return 0;
}

struct net_conn *shaped_link_session(struct shaped_link *sl, const struct daemon_env *e, bool whole,
				     uint32_t codecs, uint32_t *pid, char why[256])
{
	int fd = shaped_link_connect(sl, e->port);
	if (fd < 0) {
		err_set(why, "connect from the namespace to %s:%d: %s", sl->addr, e->port,
			strerror(-fd));
		return NULL;
	}
	char tokf[160], peer[64];
	snprintf(tokf, sizeof tokf, "%s/token", e->dir);
	snprintf(peer, sizeof peer, "%s:%d", sl->addr, e->port);
	struct net_opts o = { .token_file = tokf, .name = "shaped_link", .timeout_ms = 10000,
			      .codecs = codecs, .whole_tiles = whole };
	struct net_conn *c = NULL;
	if (net_connect_fd(fd, peer, &o, &c, why))
		return NULL;
	struct proto_msg m = { 0 };
	if (net_open_planet(c, "test", &m, 10000, why)) {
		net_close(c);
		return NULL;
	}
	*pid = m.opened.planet_id;
	proto_msg_fini(&m);
	return c;
}

/* Both layers of a side×side block of level (ly + 1, ly) around lon, lat. */
static uint32_t block(struct proto_want_entry *e, int ly, double lon, double lat, int side)
{
	uint32_t nx = 2u << ly, ny = 1u << ly, n = 0;
	long cx = (long)floor((lon + 180.0) / 360.0 * nx), cy = (long)floor((90.0 - lat) / 180.0 * ny);
	long h = side > (long)ny ? (long)ny : side; /* a short level: all its rows */
	long x0 = cx - side / 2, y0 = cy - h / 2;
	y0 = y0 < 0 ? 0 : y0 + h > (long)ny ? (long)ny - h : y0;
	for (int l = 0; l < 2; l++)
		for (long y = y0; y < y0 + h; y++)
			for (long x = x0; x < x0 + side; x++)
				e[n++] = (struct proto_want_entry){
					.layer = (uint8_t)l, .cls = PROTO_CLASS_VISIBLE,
					.lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly,
					.x = (uint32_t)((x % (long)nx + (long)nx) % (long)nx),
					.y = (uint32_t)y };
	return n;
}

static uint32_t place(struct proto_want_entry *e, int lmin, int lmax, double lon, double lat,
		      int side)
{
	uint32_t n = 0;
	for (int ly = lmin; ly <= lmax; ly++)
		n += block(e + n, ly, lon, lat, side);
	return n;
}

static int want(struct net_conn *c, uint32_t pid, uint32_t seq, double lon, double lat,
		const struct proto_want_entry *e, uint32_t n, char why[256])
{
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = seq, .lon = lon, .lat = lat,
					 .count = n, .entries = e } };
	return net_send(c, &m, why);
}

int link_jump_run(struct net_conn *c, uint32_t pid, const struct link_jump_plan *p,
		  struct link_jump_result *r, char why[256])
{
	enum { MAXE = 8192 };
	static struct proto_want_entry a[MAXE], b[MAXE];
	*r = (struct link_jump_result){ .first_ms = -1, .coarse_ms = -1, .full_ms = -1 };
	int sa = 2 * p->a_side * p->a_side, sb = 2 * p->b_side * p->b_side;
	if ((p->a_lmax - p->a_lmin + 1) * sa > MAXE || (p->b_lmax - p->b_lmin + 1) * sb > MAXE) {
		err_set(why, "jump plan too large");
		return -EINVAL;
	}
	uint32_t na = place(a, p->a_lmin, p->a_lmax, 0, 0, p->a_side);
	uint32_t nb = place(b, p->b_lmin, p->b_lmax, 120, -40, p->b_side);
	for (uint32_t i = 0; i < nb; i++)
		for (uint32_t j = 0; j < na; j++)
			if (!memcmp(&a[j].lx, &b[i].lx, 2) && a[j].x == b[i].x && a[j].y == b[i].y) {
				err_set(why, "places A and B share tile %u/%u/%u", b[i].ly, b[i].x,
					b[i].y);
				return -EINVAL;
			}
	r->b_wanted = nb;
	int rc = want(c, pid, 1, 0, 0, a, na, why);
	if (rc)
		return rc;
	uint64_t t0 = clock_now_ns(), first_a = 0, warm_bytes = 0;
	uint64_t warm_end = t0 + (uint64_t)p->warm_ms * 1000000u;
	struct proto_msg m = { 0 };
	uint64_t now;
	while ((now = clock_now_ns()) < warm_end) {
		rc = net_recv(c, &m, (int)((warm_end - now) / 1000000u) + 1, why);
		if (rc == -ETIMEDOUT)
			break;
		if (rc)
			return rc;
		if (m.type == PROTO_TILE) {
			uint64_t fb = net_last_wire(c); /* a tile in parts: all of them */
			r->max_frame = fb > r->max_frame ? fb : r->max_frame;
			if (first_a)
				warm_bytes += fb;
			else
				first_a = clock_now_ns();
		}
		proto_msg_fini(&m);
	}
	if (first_a && clock_now_ns() > first_a)
		r->warm_bps = (double)warm_bytes * 8e9 / (double)(clock_now_ns() - first_a);
	rc = want(c, pid, 2, 120, -40, b, nb, why);
	if (rc)
		return rc;
	uint64_t tj = clock_now_ns(), end = tj + (uint64_t)p->deadline_ms * 1000000u;
	/* the parts of a tile that came before the jump are not stale: they are subtracted
	 * once that tile completes (a stale TILE) or is stopped (dropped parts) */
	uint64_t dropped0 = net_parts_dropped(c), before = net_parts_open(c);
	bool first = true, open_dropped = false;
	uint32_t coarse = 0;
	while ((now = clock_now_ns()) < end) {
		rc = net_recv(c, &m, (int)((end - now) / 1000000u) + 1, why);
		if (rc == -ETIMEDOUT)
			break;
		if (rc)
			return rc;
		double at = (double)(clock_now_ns() - tj) * 1e-6;
		/* the tile open at the jump was dropped before the first message after it came,
		 * or it is that message */
		if (first)
			open_dropped = before && net_parts_dropped(c) > dropped0;
		first = false;
		if (m.type == PROTO_TILE_FAIL && m.tile_fail.seq == 2) {
			err_set(why, "tile %u/%u/%u of B failed: %s", m.tile_fail.key.ly,
				m.tile_fail.key.x, m.tile_fail.key.y, m.tile_fail.message);
			proto_msg_fini(&m);
			return -EIO;
		}
		if (m.type == PROTO_TILE) {
			uint64_t fb = net_last_wire(c);
			r->max_frame = fb > r->max_frame ? fb : r->max_frame;
			if (m.tile.seq == 1) {
				r->stale_bytes += fb;
				r->stale_tiles++;
				if (getenv("LINK_DEBUG"))
					fprintf(stderr, "stale %7.1f ms %6llu B codec %u layer %u lvl %u\n", at,
						(unsigned long long)fb, m.tile.enc.codec, m.tile.layer, m.tile.key.ly);
			} else if (m.tile.seq == 2) {
				/* whole and right, parts and all: its checksum holds */
				static float texels[256 * 256];
				char e2[256];
				if (net_tile_decode(c, &m.tile, texels, sizeof texels, e2)) {
					err_set(why, "tile %u/%u/%u of B: %s", m.tile.key.ly,
						m.tile.key.x, m.tile.key.y, e2);
					proto_msg_fini(&m);
					return -EBADMSG;
				}
				if (r->first_ms < 0) {
					r->first_ms = at;
					r->first_frame = fb;
				}
				r->b_tiles++;
				r->b_raw += m.tile.enc.codec == TCODEC_NONE;
				if (m.tile.key.ly == p->b_lmin && ++coarse == (uint32_t)sb)
					r->coarse_ms = at;
				if (r->b_tiles == nb)
					r->full_ms = at;
			}
		}
		proto_msg_fini(&m);
		if (r->full_ms >= 0 || (!p->full && r->coarse_ms >= 0))
			break;
	}
	/* A's tiles the daemon stopped between two parts: their parts came, and count */
	r->stale_cut = net_parts_dropped(c) - dropped0;
	r->stale_bytes += r->stale_cut;
	r->stale_bytes = r->stale_bytes > before ? r->stale_bytes - before : 0;
	if (open_dropped) /* else the open tile completed, and its TILE held those bytes */
		r->stale_cut = r->stale_cut > before ? r->stale_cut - before : 0;
	return 0;
}

int shaped_link_view(const struct shaped_link *sl, const struct daemon_env *e, const char *flight,
		     int fps, bool lossless, const char *stats, char *out, size_t n)
{
	if (!daemon_env_built(e, "clipmapview")) {
		snprintf(out, n, "build/clipmapview was not built");
		return -ENOTSUP;
	}
	char exe[600], tokf[600], target[64], fps_s[16];
	snprintf(exe, sizeof exe, "%s/clipmapview", e->bindir);
	snprintf(tokf, sizeof tokf, "%s/token", e->dir);
	snprintf(target, sizeof target, "%s:%d", sl->addr, e->port);
	snprintf(fps_s, sizeof fps_s, "%d", fps);
	char *argv[] = { "ip", "netns", "exec", (char *)sl->ns, exe, "--connect", target,
			 "--token-file", tokf, "--planet", "test", "--flight", (char *)flight,
			 "--steps", "1", "--fps", fps_s, "--size", "320x180", "--stats",
			 (char *)stats, "--no-prefetch", lossless ? "--lossless" : NULL, NULL };
	int rc = daemon_env_run(argv, out, n);
	if (rc == 1 && strstr(out, "no OpenGL context"))
		return -ENOTSUP;
	return rc;
}
