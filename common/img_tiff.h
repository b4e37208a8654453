/* img_tiff — private to img.cpp and img_georef.c (the libtiff side of img.h). */
#ifndef CLIPMAP_IMG_TIFF_H
#define CLIPMAP_IMG_TIFF_H
#ifdef __cplusplus
extern "C" {
#endif
/* For a TIFF: every tile or strip of every directory must lie within the file (a file cut
 * short fails, wherever the cut). Returns 0 (also for a file that is not a TIFF) or -EIO with
 * err naming the file, the tile and the directory. Reads only the directories. */
int img_tiff_check_extents(const char *path, char err[256]);
#ifdef __cplusplus
}
#endif
#endif
