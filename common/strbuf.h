/* strbuf — a growing, NUL-terminated text buffer for documents built piece by piece (metrics,
 * capabilities, HTML). Aborts on ENOMEM like xalloc. Not thread-safe (one owner). */
#ifndef CLIPMAP_STRBUF_H
#define CLIPMAP_STRBUF_H
#include <stddef.h>

struct strbuf {
	char *s; /* NUL-terminated; owned (free() it, or take it with strbuf_take) */
	size_t n, cap;
};

void strbuf_printf(struct strbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* s with XML's five special characters escaped (&amp; &lt; &gt; &quot; &apos;). */
void strbuf_xml(struct strbuf *b, const char *s);
/* s as a JSON string, quotes included (\" \\ and control characters escaped). */
void strbuf_json(struct strbuf *b, const char *s);
/* The text (malloc'ed; *len bytes without the NUL); b is left empty. */
char *strbuf_take(struct strbuf *b, size_t *len);

#endif
