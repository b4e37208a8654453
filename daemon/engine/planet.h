/* planet — a planet file (INI, conf/planets/) loaded into a graph of nodes and published
 * layers. Loading checks everything a user can get wrong (unknown keys and node types,
 * unknown or missing inputs, cycles, type mismatches, bad values) and reports the first error
 * as "file:line: key: message".
 *
 * File layout:
 *   [planet]        name, description, body = wgs84 | sphere | custom, radius, flattening,
 *                   tile_size (power of two, 64..1024), max_level; the look:
 *                   atmosphere = none | earth | mars, atmosphere_density, atmosphere_height,
 *                   atmosphere_color (overriding the preset), sea_level (absent: no sea),
 *                   sea_geoid (a geoid node the sea follows), sea_basins (an open_sea
 *                   node whose closed seas lie at their own levels), sea_mask = color_alpha
 *   [node NAME]     type = <node type>, its input slots naming other nodes, its parameters
 *   [layer NAME]    node = NAME, format = f32 | rgba8 | rg8 (optional; checked)
 *
 * Ownership: planet_load returns a reference-counted planet; planet_unref drops the
 * caller's reference and the last one frees it and its nodes. Its file nodes read through
 * one image cache (planet->images, shared with other planets when the loader is given one). A loaded planet is immutable
 * (but for its reference count) and may be shared by any number of threads.
 */
#ifndef CLIPMAP_PLANET_H
#define CLIPMAP_PLANET_H
#include <stdbool.h>
#include <stddef.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>

#include "common/seagrid.h"
#include "node.h"

struct geo_body;
struct img_cache;

/* The image cache a planet loaded on its own gets (MiB); clipmapd's [engine] image_cache_mb
 * has the same default. */
#define PLANET_IMAGE_CACHE_MB 256

struct planet_layer {
	char *name;
	struct node *node; /* borrowed from the planet */
	enum pix_type type;
	int normal_of;	   /* a normal layer that is the `normal` (exaggeration 1) of the node of
			    * height layer normal_of: that index (a viewer can make these normals
			    * itself); else -1 */
};

/* How the planet looks beyond its layers: its air and its sea (docs/PLANETS.md). */
struct planet_look {
	double air_density;   /* haze relative to Earth's; 0: no atmosphere (black sky) */
	double air_height;    /* scale height, metres (> 0 with air, 0 without) */
	uint8_t air_color[3]; /* the sky's colour at the ground, sRGB; its hue tints the haze */
	bool sea;	      /* a sea at sea_level covers what lies below it */
	double sea_level;     /* metres above the ellipsoid (0 without a sea) */
	bool sea_mask;	      /* sea_mask = color_alpha: the colour layers' alpha says where a sea
			       * may lie (254 of 255: dry land, even below sea level) */
	/* With `sea_geoid = NODE`: the sea lies on that geoid node's geoid, sea_level above it;
	 * with `sea_basins = NODE`, that open_sea node's levelled closed seas at their levels
	 * (a 1° lattice of it; owned). 0 × 0: at sea_level everywhere. */
	struct sea_grid sea_grid;
};

struct planet {
	/* References: planet_load gives the caller one; the scheduler holds one per job on the
	 * planet's nodes, so a planet dropped while workers still generate from it lives until
	 * they finish. 0 marks a caller-owned planet (tests fill one by hand): never freed. */
	atomic_int refs;
	char *name;
	char *description;
	char *path; /* the planet file */
	char *dir;  /* its directory: relative data paths resolve against it */
	double a, f;
	struct geo_body *body;
	uint32_t tile_size;
	int max_level; /* finest ly; lx ≤ max_level + 1 */
	struct planet_look look;
	struct node **nodes; /* topological order: every node after its inputs */
	size_t nnodes;
	struct planet_layer *layers;
	size_t nlayers;
	struct ini_file *ini; /* kept: node parameters borrow strings from it */
	/* The image cache every file node of the planet reads through: one reference, dropped
	 * after the nodes. NULL only in caller-owned planets (file nodes then make their own). */
	struct img_cache *images;
};

/* The look of a preset atmosphere ("none", "earth", "mars"), without a sea. Returns 0, or
 * -EINVAL for another name. */
int planet_look_preset(const char *name, struct planet_look *out);

/* Loads and checks a planet file. Returns 0 or -errno with err filled. */
int planet_load(const char *path, struct planet **out, char err[256]);
/* planet_load, resolving node types in `types` (NULL-terminated, borrowed; must outlive the
 * planet) instead of node_types_all() — for tests and tools that add their own types. */
int planet_load_types(const char *path, const struct node_type *const *types, struct planet **out,
		      char err[256]);
/* The general form: types as planet_load_types (NULL: node_types_all()); images is the
 * image cache its file nodes share (the planet takes a reference of its own; NULL: the planet
 * creates one of PLANET_IMAGE_CACHE_MB). A file whose size, mtime or inode differ from what
 * an earlier load recorded in images is invalidated there, so the new planet reads the new
 * pixels. */
int planet_load_shared(const char *path, const struct node_type *const *types,
		       struct img_cache *images, struct planet **out, char err[256]);
/* Another reference (for the scheduler); no-op for NULL or caller-owned planets. */
void planet_ref(const struct planet *p);
/* Drops a reference: planet_load's or one taken with planet_ref (NULL is a no-op); the last
 * one frees the planet and its nodes. */
void planet_unref(const struct planet *p);
/* path as a node's data path: relative paths resolve against the planet file's directory.
 * Returns an owned string. */
char *planet_resolve_path(const struct planet *p, const char *path);
struct node *planet_find_node(const struct planet *p, const char *name);
const struct planet_layer *planet_find_layer(const struct planet *p, const char *name);
/* Writes the graph as Graphviz dot. Returns 0 or -errno. */
int planet_write_dot(const struct planet *p, FILE *f);

#endif
