/* view — the viewer: spherical clipmap rendering (seed 000) with the per-frame update and
 * render loop of seed 003 Algorithm 1 over a view_source, into an offscreen framebuffer.
 *
 * Each frame: compute the levels the camera needs (view_levels.h); when a level's target quad
 * moves, send the new want-set (quads coarse first, then the ring around them); take the tiles
 * that arrived; then for each level coarse → fine, update its textures if its quad is complete
 * (the time budget limits these uploads: the frame's first always, more while they have
 * taken less than the budget)
 * and draw it as a ring when the next level can be drawn (its texture covers its ring, new or
 * resident), else as a full disk, and stop. What is resident is drawn every frame, so a still
 * camera never loses a level. It never waits for a tile.
 *
 * Threads: the GL context's thread only. Ownership: borrows gl and the source (both must
 * outlive the view); owns its GL objects and clipmap.
 */
#ifndef CLIPMAP_VIEW_H
#define CLIPMAP_VIEW_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "gl_context.h"
#include "view_clipmap.h"
#include "view_levels.h"
#include "view_source.h"

/* The default sun: from the north-west, so that a north-up view is lit from its upper left
 * (the light the eye assumes: craters read as bowls, not domes), 35° up. */
#define VIEW_SUN_AZ 315
#define VIEW_SUN_EL 35

/* Where the normals come from. FETCH: the planet's normal layer (none: flat shading); DERIVE:
 * the viewer makes them from its height clipmap as heights are uploaded (the `normal` node's
 * arithmetic, view_clipmap) and never asks for the normal layer — a third fewer bytes (Earth:
 * 20 of a place's 57 KB on a slow link); AUTO (0): DERIVE where that draws what the normal
 * layer holds (the planet says its normal layer is the plain `normal` of its heights) or the
 * planet has no normal layer, else FETCH. */
enum view_normals { VIEW_NORMALS_AUTO = 0, VIEW_NORMALS_FETCH, VIEW_NORMALS_DERIVE };

struct view_desc {
	int width, height;  /* framebuffer; 0: 1280×720 */
	int n_phi;	    /* steps around each ring; 0: 256 */
	int m_rings;	    /* rings per level; 0: 16 */
	bool no_prefetch;   /* want only the visible quads */
	double fade_s;	    /* a level that becomes drawable fades in over this long (0: at once) */
	double budget_ms;   /* upload no more new quads once a frame's uploads have taken this
			     * long (its first always; resident levels are drawn anyway; 0: no
			     * limit) */
	bool background_set;
	float background[3]; /* the clear colour (linear 0..1); default: space, sky near ground */
	float sun_az, sun_el; /* degrees, at the camera, azimuth clockwise from north; both 0:
			       * VIEW_SUN_AZ, VIEW_SUN_EL */
	float exaggeration;   /* vertical exaggeration of the relief; 0: 1 (true scale) */
	float haze;	      /* atmosphere density, 1: Earth's; 0: the planet's (its look); < 0:
			       * none. > 0 gives a planet without air Earth's */
	bool no_cull;	      /* draw every ring sector (also: CLIPMAP_NO_CULL=1 in the env) */
	bool unlit;	      /* the colour layer as it is: no sun, air or water (measuring what
			       * the textures put on screen) */
	const char *color_layer; /* the colour layer drawn (borrowed); NULL: the one named
				  * "color", else the first colour layer */
	enum view_normals normals; /* where the shading's normals come from */
};

struct view_frame_stats {
	double cpu_ms;	      /* the frame's CPU time including glFinish */
	int lmin, lmax;	      /* levels the camera wants drawn (geometry) */
	int dmax;	      /* the finest level it wants for texture (lmax + CLIPMAP_DETAIL at most) */
	int lfirst, llast;    /* the coarsest and finest level drawn (-1: none) */
	int levels_drawn;     /* how many (levels between them whose texture is not ready are
			       * left out, the coarser level drawn over their rings) */
	int ldetail;	      /* the finest level whose colour and normals are drawn (-1: none) */
	uint64_t triangles;	   /* drawn */
	uint64_t triangles_culled; /* in the drawn levels' geometry, left out by frustum culling */
	uint64_t bytes_uploaded; /* this frame */
	int levels_uploaded;	 /* levels whose new quad was copied in this frame */
	int tiles_received;	 /* this frame */
	size_t wants_sent;	 /* entries in the want-set sent this frame (0: none sent) */
	bool complete;		 /* every wanted level drawn at its target quad (its colour
				  * from the colour layer drawn now) */
	const char *color_layer; /* the colour layer drawn ("" none; borrowed from the source) */
	double alt, agl, ground; /* camera above the ellipsoid, above the ground; ground height
				  * (the water's surface where a sea covers the ground) */
};

struct view;

/* Builds the clipmap, the ring geometry, the shaders and the framebuffer. Returns 0 or -errno
 * with err filled. */
int view_create(const struct gl *gl, struct view_source *src, const struct view_desc *d,
		struct view **out, char err[256]);
void view_destroy(struct view *v);

/* Renders one frame. c->alt is the camera's height above the ground (the terrain under it as
 * far as the clipmap knows it). now_s drives fades. Returns 0 or -errno. */
int view_frame(struct view *v, const struct view_camera *c, double now_s,
	       struct view_frame_stats *st);
/* Between frames: takes the tiles that arrive for the next `seconds` (they are uploaded by
 * the next frame, within its budget). Returns how many arrived, or -errno. */
int view_idle(struct view *v, double seconds);
/* Switches the colour layer drawn to the planet's colour layer `name` from the next frame
 * on: its tiles are wanted coarse levels first, and each level keeps its old colour until
 * its new one is complete (view_clipmap_set_color); heights and normals stay. Returns 0, or
 * -EINVAL with err naming the planet's colour layers. */
int view_set_color_layer(struct view *v, const char *name, char err[256]);
/* The index of the planet's colour layer `name` (what view_set_color_layer takes), or
 * -EINVAL with err naming the planet's colour layers. */
int view_find_color_layer(const struct view *v, const char *name, char err[256]);
/* The colour layer drawn, or the one asked for if the switch is still to come (NULL: the
 * planet has none); borrowed from the source. */
const char *view_color_layer(const struct view *v);
/* Turns frustum culling of ring sectors on or off (a debug switch: the pixels are the same). */
void view_set_culling(struct view *v, bool on);
/* The rings' density: 0 (the default) every vertex below MESH_HALF_ABOVE × the planet's
 * radius above the ground and every other one above it, where no relief reaches a pixel;
 * 1 always every vertex; 2 always every other one (for comparing the two). */
void view_set_mesh(struct view *v, int mode);
/* Offline rendering: renders frames, sleeping on the source between them, until one is
 * complete (every wanted level drawn at its target quad, the camera's ground height settled)
 * or timeout_s passes. *frames (may be NULL) counts the frames. Returns 0 or -ETIMEDOUT (the
 * last frame is still in the framebuffer) or another -errno. */
int view_frame_complete(struct view *v, const struct view_camera *c, double timeout_s,
			struct view_frame_stats *st, int *frames);
/* Rebuilds the framebuffer at width×height (a window's new size); the clipmap is kept.
 * Returns 0 or -errno with err filled. */
int view_resize(struct view *v, int width, int height, char err[256]);
/* The framebuffer object the frames are drawn into (to blit it to a window). */
unsigned view_framebuffer(const struct view *v);
/* The camera of the last frame with its height above the ellipsoid. */
void view_last_camera(const struct view *v, struct view_camera *out);
/* Reads the last frame as RGBA8, top row first (width·height·4 bytes). Returns 0. */
int view_read_rgba(struct view *v, unsigned char *out);
struct view_clipmap *view_get_clipmap(struct view *v);
const struct view_body *view_get_body(const struct view *v);
/* The clear colour in the framebuffer's 8-bit encoding. */
void view_background_rgba(const struct view *v, unsigned char out[4]);

#endif
