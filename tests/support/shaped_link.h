/* shaped_link — a real shaped network link for tests and benchmarks: the daemon's end of a
 * veth pair here (an address clipmapd can listen on), the client's end in a network namespace,
 * and between them a third namespace where a relay process copies the Ethernet frames from one
 * veth pair to the other, holding what the daemon sends to the given rate (serialised in order,
 * a queue of SHAPED_QUEUE_BYTES, tail drop) and delay (one way, so the round trip is the delay)
 * — what netem does, which this kernel may lack (tc's netem is used by nobody here: the relay
 * works wherever AF_PACKET does). Frames keep their virtio-net header (PACKET_VNET_HDR), so
 * checksum offload and GSO pass through; the daemon's end sends MTU-sized segments
 * (gso_max_segs 1) so the rate is kept per packet. Client sockets are made inside the
 * namespace (setns around socket+connect). Everything is removed by shaped_link_fini, at exit
 * and on SIGINT/SIGTERM/SIGHUP/SIGPIPE; namespaces left by a test killed with SIGKILL are
 * removed by the next setup.
 *
 * Also the jump scenario the shaped-link test and bench_link measure: a session streams a
 * large want-set at place A, then jumps (a new want-set at place B, no tile in common) — how
 * long until B's first tile, B's coarsest level, all of B, and how many of A's bytes still
 * came after the jump.
 *
 * Test-only code. Needs root and ip(8); shaped_link_init says why not.
 */
#ifndef CLIPMAP_TEST_SHAPED_LINK_H
#define CLIPMAP_TEST_SHAPED_LINK_H
#include <stdbool.h>
#include <stdint.h>

struct net_conn;

#include <sys/types.h>

#define SHAPED_QUEUE_BYTES (1500u * 1000u) /* the shaped direction's queue (netem's default) */

struct shaped_link {
	char ns[32];	      /* the client's namespace ("" when none) */
	char mid[40];	      /* the relay's namespace */
	pid_t relay;	      /* the relay process (0: none) */
	char dev[16], peer[16]; /* the veth ends: dev here, peer in ns */
	char addr[24];	      /* dev's address: where the daemon listens */
	char peer_addr[24];
	bool up;
};

/* Makes the namespace and the link (unshaped). Returns 0; -ENOTSUP with why filled when it
 * cannot be done here (not root, no ip or tc, no netem, namespaces refused): skip then; or
 * another -errno. */
int shaped_link_init(struct shaped_link *sl, char why[256]);
/* Shapes what goes from the daemon's side to the client: rate_kbit, delay_ms one way (the
 * relay is restarted with them; frames queued in the old one are lost). Returns 0 or -errno
 * (why filled). */
int shaped_link_shape(struct shaped_link *sl, unsigned rate_kbit, unsigned delay_ms,
		      char why[256]);
/* A TCP socket connected from the namespace to addr:port (blocking). Returns the fd or
 * -errno. */
int shaped_link_connect(struct shaped_link *sl, int port);
/* Removes the namespace (and with it the link). Idempotent. */
void shaped_link_fini(struct shaped_link *sl);
/* fn runs first when the link is removed at exit or on a signal (the caller's daemon: stop it
 * there, so that a test stopped by SIGTERM leaves nothing running). */
void shaped_link_on_fini(void (*fn)(void));

/* The scenario's planet (tile_size 128: tiles of 64 KiB raw, about 50 KB with zstd; a height
 * and a colour layer), to write into the daemon's planets as "test". */
extern const char shaped_link_planet[];
struct daemon_env;
/* A session to the daemon of e (listening on sl->addr, token file DIR/token) from the client's
 * namespace, planet "test" open (its id in *pid), offering codecs (0: the lossless ones) and,
 * unless whole, to reassemble TILE_PART. Returns it, or NULL with why filled. */
struct net_conn *shaped_link_session(struct shaped_link *sl, const struct daemon_env *e, bool whole,
				     uint32_t codecs, uint32_t *pid, char why[256]);

/* Starts clipmapd in e (daemon_env_init with tag, the planet above as "test", the token)
 * listening on sl->addr, with 2 workers, a 256 MB cache, max_rate 1000, log level info and
 * the config lines in extra (NULL-terminated, may be NULL; at most 8). Returns 0, or -1 with
 * why filled and e finished. */
int shaped_link_daemon_start(const struct shaped_link *sl, struct daemon_env *e, const char *tag,
			     const char *token, const char *const *extra, char why[256]);

/* The jump scenario: the planet's layers 0 and 1, VISIBLE. */
struct link_jump_plan {
	int warm_ms;	     /* streaming A before the jump */
	int a_lmin, a_lmax, a_side; /* A: levels ly a_lmin..a_lmax, a_side² tiles each, per layer */
	int b_lmin, b_lmax, b_side; /* B likewise; B's coarsest level is b_lmin */
	bool full;	     /* wait for all of B (else until B's coarsest level is complete) */
	int deadline_ms;     /* after the jump, at most */
};

struct link_jump_result {
	double warm_bps;	      /* goodput received before the jump (bits/s) */
	uint64_t max_frame;	      /* the largest TILE frame received (bytes; in parts: all) */
	uint64_t first_frame;	      /* the new place's first tile's frames (bytes) */
	double first_ms, coarse_ms, full_ms; /* after the jump; < 0: not within the deadline */
	uint64_t stale_bytes, stale_tiles;   /* A's TILE frames received after the jump, and */
	uint64_t stale_cut;		     /* of those bytes, parts of tiles stopped midway */
	uint32_t b_tiles, b_wanted;
	uint32_t b_raw; /* B's tiles sent raw (codec none) */
};

/* Runs the scenario on c (HELLO done, planet pid open with at least two layers; A at lon 0,
 * lat 0 and B at lon 120, lat -40). Returns 0 (r filled, also when the deadline passed), or
 * -errno with why filled (the connection failed). */
int link_jump_run(struct net_conn *c, uint32_t pid, const struct link_jump_plan *p,
		  struct link_jump_result *r, char why[256]);

/* Runs build/clipmapview (offscreen, 320x180, fps frames a second, --no-prefetch) in the
 * client's namespace against the daemon of e, flying the camera keys of CSV flight (one key
 * per frame), --lossless when asked, one --stats line per frame into stats. Returns its exit
 * status (0 ok), -ENOTSUP with out saying why when there is no GL context or no clipmapview,
 * or -errno; out (n bytes) gets its output. */
int shaped_link_view(const struct shaped_link *sl, const struct daemon_env *e, const char *flight,
		     int fps, bool lossless, const char *stats, char *out, size_t n);

#endif
