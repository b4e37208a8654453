/* strbuf — see strbuf.h. */
#include "common/strbuf.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "common/xalloc.h"

void strbuf_printf(struct strbuf *b, const char *fmt, ...)
{
	if (!b->s) {
		b->cap = 4096;
		b->s = xmalloc(b->cap);
		b->n = 0;
		b->s[0] = '\0';
	}
	for (;;) {
		va_list ap;
		va_start(ap, fmt);
		int k = vsnprintf(b->s + b->n, b->cap - b->n, fmt, ap);
		va_end(ap);
		if (k < 0)
			return;
		if ((size_t)k < b->cap - b->n) {
			b->n += (size_t)k;
			return;
		}
		b->cap = b->cap * 2 + (size_t)k;
		b->s = xrealloc(b->s, b->cap);
	}
}

void strbuf_xml(struct strbuf *b, const char *s)
{
	for (; s && *s; s++)
		switch (*s) {
		case '&': strbuf_printf(b, "&amp;"); break;
		case '<': strbuf_printf(b, "&lt;"); break;
		case '>': strbuf_printf(b, "&gt;"); break;
		case '"': strbuf_printf(b, "&quot;"); break;
		case '\'': strbuf_printf(b, "&apos;"); break;
		default: strbuf_printf(b, "%c", *s);
		}
}

void strbuf_json(struct strbuf *b, const char *s)
{
	strbuf_printf(b, "\"");
	for (; s && *s; s++) {
		unsigned char c = (unsigned char)*s;
		if (c == '"' || c == '\\')
			strbuf_printf(b, "\\%c", c);
		else if (c < 0x20)
			strbuf_printf(b, "\\u%04x", c);
		else
			strbuf_printf(b, "%c", c);
	}
	strbuf_printf(b, "\"");
}

char *strbuf_take(struct strbuf *b, size_t *len)
{
	strbuf_printf(b, "%s", ""); /* allocated even when nothing was written */
	char *s = b->s;
	if (len)
		*len = b->n;
	*b = (struct strbuf){ 0 };
	return s;
}
