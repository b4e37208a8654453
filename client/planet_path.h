/* planet_path — where a planet named on the command line lives: a path (contains '/' or ends
 * in .ini) is used as is; a bare name is looked up as NAME.ini in $CLIPMAP_PLANETS,
 * ./conf/planets, <executable>/../conf/planets and /etc/clipmap/planets (where `make install`
 * puts them). Pure lookup, no state. */
#ifndef CLIPMAP_PLANET_PATH_H
#define CLIPMAP_PLANET_PATH_H
#include <stddef.h>

/* Fills out (size n) with the file to load. Returns 0 or -ENOENT (out then holds the first
 * candidate tried, for the message). */
int planet_path_resolve(const char *arg, char *out, size_t n);

#endif
