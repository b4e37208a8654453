/* errbuf — filling the optional `char err[256]` that library functions hand back to a human.
 * Thread-safe (writes only the caller's buffer). */
#ifndef CLIPMAP_ERRBUF_H
#define CLIPMAP_ERRBUF_H
#include <stdarg.h>

#ifdef __cplusplus
extern "C" {
#endif

/* printf into err (256 bytes, cut at 255); NULL err is a no-op. */
void err_set(char *err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* err_set with a va_list, for functions that format on behalf of their caller. */
void err_vset(char *err, const char *fmt, va_list ap) __attribute__((format(printf, 2, 0)));
/* err_set, returning -EINVAL: `return err_inval(err, "...", ...);` for a bad argument. */
int err_inval(char *err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* A config error as "path:line: key: message": the line is left out when <= 0, the key when
 * NULL. NULL err is a no-op. */
void err_vset_at(char *err, const char *path, int line, const char *key, const char *fmt,
		 va_list ap) __attribute__((format(printf, 5, 0)));

#ifdef __cplusplus
}
#endif

#endif
