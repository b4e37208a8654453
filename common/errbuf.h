/* errbuf — filling the optional `char err[256]` that library functions hand back to a human.
 * Thread-safe (writes only the caller's buffer). */
#ifndef CLIPMAP_ERRBUF_H
#define CLIPMAP_ERRBUF_H

/* printf into err (256 bytes); NULL err is a no-op. */
void err_set(char *err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

#endif
