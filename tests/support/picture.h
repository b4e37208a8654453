/* picture — what the tests ask of a picture a viewer wrote: whether it has terrain in it.
 * Test-only code; no state. */
#ifndef CLIPMAP_TEST_PICTURE_H
#define CLIPMAP_TEST_PICTURE_H

/* The spread of the green channel (max − min, 0..255) over the picture at path: a broken
 * source shows the clear colour only (spread about 0), terrain spreads it. -1 when the file
 * cannot be read as a picture. */
double picture_spread(const char *path);

#endif
