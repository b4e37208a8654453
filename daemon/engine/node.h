/* node — one image source of the planet graph (seed 003 §4.1) and the interface every node
 * type implements. A node's output for a tile key depends only on its parameters and its
 * inputs' tiles, so generation is deterministic and the node's content hash (type, version,
 * parsed parameters, input hashes) names its tiles everywhere.
 *
 * Threads: after planet_load returns, nodes are immutable except their atomic counters;
 * deps() and generate() are called from any worker concurrently and must not write to the
 * node. Per-call scratch memory comes from the worker's gen_ctx.
 */
#ifndef CLIPMAP_NODE_H
#define CLIPMAP_NODE_H
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "common/grid.h"
#include "common/ini.h"
#include "tile.h"

#define NODE_MAX_INPUTS 4
#define NODE_MAX_DEPS 16

struct node;
struct planet;

/* An input slot of a node type; in the planet file it is a key naming another node. */
struct node_slot {
	const char *name;   /* e.g. "input", "a", "b", "mask", "height" */
	enum pix_type type; /* required output type of the input; PIX_NONE accepts any */
	bool optional;
	/* The node reads a summary of this input's height tiles (tile.h: lo, hi, any NaN): the
	 * input's tiles are summarized as they are made. */
	bool summary;
};

/* One tile a generation needs: a node and a key (key.node = that node's hash). */
struct node_dep {
	struct node *node;
	struct tile_key key;
};

/* Per-worker state handed to generate(); scratch memory is reused across calls. */
struct gen_ctx {
	void *scratch;
	size_t cap;
	int worker;
};
/* At least n bytes of 64-byte-aligned scratch, valid until the next call on this ctx. */
void *gen_scratch(struct gen_ctx *g, size_t n);
void gen_ctx_fini(struct gen_ctx *g);

/* Parameter reading while a node is created. Every getter marks the key used, feeds the key
 * and the canonical parsed value into the node's content hash, and on error fills p->err with
 * "file:line: key: message" and returns -EINVAL. Missing keys take the default. */
struct node_parse {
	const char *file;
	struct ini_section *sec;
	void *hash_state; /* XXH3 state, owned by the loader */
	char *err;	  /* 256 bytes */
};
int np_double(struct node_parse *p, const char *key, double def, double lo, double hi, double *out);
int np_int(struct node_parse *p, const char *key, long def, long lo, long hi, long *out);
/* A string; *out borrows from the ini data (valid until planet_unref: the loader keeps it). */
int np_string(struct node_parse *p, const char *key, const char *def, const char **out);
/* One of `names` (NULL-terminated); *out is its index. */
int np_enum(struct node_parse *p, const char *key, const char *const *names, int def, int *out);
/* "#rrggbb", "#rrggbbaa" or "r,g,b[,a]" (0–255). */
int np_color(struct node_parse *p, const char *key, const uint8_t def[4], uint8_t out[4]);
/* A comma/space separated list of numbers; *n = how many (≤ max). Missing → *n = 0. */
int np_doubles(struct node_parse *p, const char *key, double *out, int max, int *n);
/* Feeds extra bytes into the content hash (e.g. a data file's size and mtime). */
void np_hash_bytes(struct node_parse *p, const void *data, size_t n);
/* Fills p->err with "file:line: key: message" for the entry `key` (the section line if the
 * key is absent) and returns -EINVAL. */
int np_error(struct node_parse *p, const char *key, const char *fmt, ...)
	__attribute__((format(printf, 3, 4)));

struct node_type {
	const char *name; /* the planet file's `type = ...` */
	const char *doc;  /* one line, for `clipmapctl graph` and the docs */
	unsigned version; /* bump when the output for the same parameters changes */
	const struct node_slot *slots;
	int nslots;
	/* Reads parameters, sets n->out (the output type) and n->impl. Inputs are already
	 * created (n->in[i]->out is known; absent optional slots are NULL). Returns 0 or
	 * -EINVAL with p->err filled. */
	int (*create)(struct node *n, struct node_parse *p);
	void (*destroy)(struct node *n); /* frees n->impl (node_free_impl: one plain
					  * allocation); may be NULL */
	/* The tiles generate() needs for key k, in order; returns how many (≤ NODE_MAX_DEPS) or
	 * -errno. NULL means: key k on every present input, in slot order. */
	int (*deps)(const struct node *n, const struct tile_key *k, struct node_dep *out);
	/* Fills out->data (out->type == n->out, out->size == tile size) from the dependency tiles
	 * in deps() order. No locks held. Returns 0 or -errno (e.g. -EIO on an unreadable file). */
	int (*generate)(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			struct tile *const *in, int nin, struct tile *out);
	/* Optional, both or neither: dependencies that may prove not needed (a blend's b where
	 * its mask is 0 on the whole tile). lazy() names them (bits, in deps() order). Where the
	 * parent key's were not needed lately (jobtab's skip memory: a skip, or generate()
	 * setting tile.lazy_unneeded) the scheduler makes the others first and, once it holds
	 * them all, asks needed() about each lazy one (in[] holds the others, NULL in the lazy
	 * slots) and makes only those it says yes to; generate() gets NULL for the rest.
	 * Elsewhere they are made at once like any input. The output must be the same bytes
	 * whether a dependency was skipped or not: what needed() refuses must be what generate()
	 * would not have read. Any thread, like deps(); k NULL: the bits for every key (a type
	 * whose lazy inputs depend on the key must then name them all). */
	uint32_t (*lazy)(const struct node *n, const struct tile_key *k);
	bool (*needed)(const struct node *n, int k, struct tile *const *in, int nin);
	/* Tiles of this type cost far more than a per-texel filter's (noise, craters): worth
	 * leaving out where a lazy input allows (node_exclusive_costly). */
	bool costly;
	/* Its tiles are read by its own tiles one level finer (a from_parent noise node's carry):
	 * a tile is the start of every finer tile's chain below it, and the cache keeps it as it
	 * keeps layer tiles (cache.h). */
	bool lineage;
};

#define NODE_GEN_BUCKETS 12 /* 0.25, 0.5, 1, … 256 ms, and longer */

struct node {
	char *name;
	const struct node_type *type;
	enum pix_type out;
	uint64_t hash;
	struct node *in[NODE_MAX_INPUTS]; /* by slot index; borrowed (the planet owns nodes) */
	const struct planet *planet;	  /* borrowed */
	void *impl;			  /* owned by the node type */
	int line;			  /* its section's line in the planet file */
	bool summarize; /* height tiles summarized as they are made (a slot's summary) */
	atomic_uint_fast64_t generated;	  /* tiles generated */
	atomic_uint_fast64_t gen_ns;	  /* total generation time */
	/* generation times: counts at most node_gen_bound_ms(i) (the last bucket: longer) */
	atomic_uint_fast64_t gen_hist[NODE_GEN_BUCKETS];
};

/* Counts one generation of n that took ns (generated, gen_ns, gen_hist). Any thread. */
void node_count_generation(struct node *n, uint64_t ns);
/* The upper bound of histogram bucket i < NODE_GEN_BUCKETS - 1, in ms: 0.25 · 2^i. */
double node_gen_bound_ms(int i);

/* Initialises node n as type t from its planet-file section (whose `type` and input-slot keys
 * the caller has already marked used) with n->name, n->planet and n->in[] already set: runs
 * t->create, refuses keys nobody read ("unknown key"), and computes n->hash from the type, its
 * version, the parsed parameters and the inputs' hashes. Returns 0 or -EINVAL with err filled
 * ("file:line: key: message"). */
int node_init(struct node *n, const struct node_type *t, const char *file, struct ini_section *sec,
	      char err[256]);
/* The destroy of a type whose n->impl is one plain allocation: frees it. */
void node_free_impl(struct node *n);
/* The optional height input in[0] of a node whose first slot may be empty: *src is NULL
 * without one. Returns 0, or -EINVAL when the tile given is not a T×T height tile. */
int node_opt_height_input(const struct node *n, struct tile *const *in, int nin, uint32_t T,
			  const struct tile **src);
/* Frees what node_init and the type allocated (not n itself, nor n->name). */
void node_fini(struct node *n);
/* Node deps() helper: key k on every present input. */
int node_default_deps(const struct node *n, const struct tile_key *k, struct node_dep *out);
/* Whether a node reachable from `from` but from none of others[0..n) (NULL entries skipped;
 * their inputs that are themselves lazy not followed) is of a costly type: what skipping
 * `from` would save besides cheap filters. */
bool node_exclusive_costly(const struct node *from, const struct node *const *others, int n);
/* The node type registry. */
const struct node_type *node_type_find(const char *name);
/* NULL-terminated list of every node type. */
const struct node_type *const *node_types_all(void);

#endif
