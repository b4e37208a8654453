/* pixfmt — the one definition of texel formats: what a node produces, what a layer publishes
 * and what a TILE carries on the wire (the numbers are the wire's format byte). Pure
 * functions, thread-safe. */
#ifndef CLIPMAP_PIXFMT_H
#define CLIPMAP_PIXFMT_H
#include <stddef.h>

/* 0 is invalid so a zeroed struct is "unset". */
enum pix_type {
	PIX_NONE = 0,
	PIX_HEIGHT = 1, /* "f32": float32 metres above the body's ellipsoid */
	PIX_COLOR = 2,	/* "rgba8": RGBA8, sRGB, straight (not premultiplied) alpha */
	PIX_NORMAL = 3, /* "rg8": east and north components of the unit normal in the local
			 * tangent frame, each mapped [-1, 1] → [0, 255] as round((c + 1) · 127.5);
			 * up = sqrt(1-e²-n²) */
	PIX_COUNT
};

/* Whether v (e.g. a byte from the wire) names a format. */
static inline int pix_valid(unsigned v)
{
	return v > PIX_NONE && v < PIX_COUNT;
}
size_t pix_bytes(enum pix_type t);	      /* bytes per texel: 4, 4, 2; 0 when invalid */
const char *pix_type_name(enum pix_type t);   /* "height", "color", "normal"; "none" */
enum pix_type pix_type_parse(const char *s);  /* PIX_NONE when unknown */
const char *pix_format_name(enum pix_type t); /* "f32", "rgba8", "rg8"; "none" when invalid */
enum pix_type pix_format_parse(const char *s); /* PIX_NONE when unknown */
/* Expands n RG8 normals (east, north) to RGB8 with the implied up component, each mapped
 * (c + 1) · 127.5: the picture form of a normal tile, shared by every writer (clipmapctl
 * render and tile, the HTTP endpoint) so their bytes agree. */
void pix_normals_rgb(const unsigned char *rg, unsigned char *rgb, size_t n);

#endif
