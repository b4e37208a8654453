/* planets — the set of planets a daemon serves: every *.ini in the planets directory, loaded
 * as one immutable, reference-counted snapshot. SIGHUP loads a new snapshot and rebinds open
 * sessions to it; sessions keep references to the snapshots they wanted nodes from, so nodes
 * the scheduler may still be working on stay alive until they let go. Unchanged nodes keep
 * their content hash, so their cached tiles stay valid across reloads. Every planet of a set
 * reads its files through one image cache (the set's `images`), which a reload passes on to
 * the next set: unchanged files stay cached, changed ones are reread.
 *
 * Threads: a snapshot is immutable; refcounts are atomic. Ownership: planet_set_load returns
 * one owned reference; planet_set_ref adds one; planet_set_unref frees at zero.
 */
#ifndef CLIPMAP_PLANETS_H
#define CLIPMAP_PLANETS_H
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "planet.h"

struct img_cache;

struct planet_set {
	atomic_int refs;
	uint64_t generation; /* increases with every load in this process */
	struct planet **planets; /* sorted by name; owned */
	size_t n;
	struct img_cache *images; /* one reference; every planet holds one too */
	/* planet_set_load_each: the files left out, as "file:line: key: message"; owned */
	char **skipped;
	size_t nskipped;
};

/* Loads every "*.ini" in dir (sorted by file name), all reading through the image cache
 * `images` (borrowed: the set and its planets take references; pass the previous set's on a
 * reload. NULL: the set creates one of PLANET_IMAGE_CACHE_MB). Returns 0 or -errno with err
 * filled ("file:line: key: message" for the first bad file; duplicate planet names are an
 * error). */
int planet_set_load(const char *dir, uint64_t generation, struct img_cache *images,
		    struct planet_set **out, char err[256]);
/* planet_set_load, except that each file loads on its own: one that fails (or repeats a
 * planet's name) is left out and its error kept in s->skipped. Fails as planet_set_load does
 * when the directory cannot be read, on ENOMEM, and when files were skipped and none
 * loaded. */
int planet_set_load_each(const char *dir, uint64_t generation, struct img_cache *images,
			 struct planet_set **out, char err[256]);
struct planet_set *planet_set_ref(struct planet_set *s);
void planet_set_unref(struct planet_set *s); /* NULL is a no-op */
/* The planet named name, or NULL (borrowed from the set). */
struct planet *planet_set_find(const struct planet_set *s, const char *name);
/* Whether any node of the set has content hash h. */
int planet_set_has_node(const struct planet_set *s, uint64_t h);

#endif
