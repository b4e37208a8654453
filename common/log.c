/* log — see log.h. The threshold and the journal flag are atomics so reading them from any
 * thread is race-free. */
#include "log.h"

#include <errno.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdlib.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static atomic_int threshold = LOG_INFO;
static atomic_bool journal;

bool log_detect_journal(void)
{
	/* systemd sets JOURNAL_STREAM=DEV:INODE for the stream it connected to stdout/stderr;
	 * stderr is the journal only when it is still that very stream (not redirected since). */
	const char *js = getenv("JOURNAL_STREAM");
	unsigned long long dev, ino;
	struct stat st;
	bool on = js && sscanf(js, "%llu:%llu", &dev, &ino) == 2 &&
		  fstat(STDERR_FILENO, &st) == 0 && (unsigned long long)st.st_dev == dev &&
		  (unsigned long long)st.st_ino == ino;
	atomic_store(&journal, on);
	return on;
}

void log_set_level(enum log_level level)
{
	atomic_store(&threshold, level == LOG_DEFAULT ? LOG_INFO : (int)level);
}

int log_parse_level(const char *s, enum log_level *out)
{
	static const char *const names[] = { "", "error", "warn", "info", "debug" };
	for (int i = 1; i <= LOG_DEBUG; i++) {
		if (strcmp(s, names[i]) == 0) {
			*out = (enum log_level)i;
			return 0;
		}
	}
	return -EINVAL;
}

/* The escape of the character at p (one or more bytes: *used), into out; returns its length,
 * or 0 when it needs none (then *used is the whole UTF-8 sequence, so a cut never splits it).
 * quote_bs: a backslash is doubled (log_escape) or left alone (log_msg's safety net, which
 * must not double what log_escape already quoted). */
static size_t escape_at(const unsigned char *p, bool quote_bs, size_t *used, char out[8])
{
	unsigned c = p[0];
	*used = 1;
	if (c == '\\' && quote_bs)
		return (size_t)snprintf(out, 8, "\\\\");
	if (c == '\n' || c == '\r' || c == '\t')
		return (size_t)snprintf(out, 8, "\\%c", c == '\n' ? 'n' : c == '\r' ? 'r' : 't');
	if (c < 0x20 || c == 0x7f)
		return (size_t)snprintf(out, 8, "\\x%02x", c);
	if (c == 0xc2 && p[1] >= 0x80 && p[1] <= 0x9f) { /* C1 controls: U+0080..U+009F */
		*used = 2;
		return (size_t)snprintf(out, 8, "\\x%02x", p[1]);
	}
	size_t len = c >= 0xf0 ? 4 : c >= 0xe0 ? 3 : c >= 0xc0 ? 2 : 1;
	while (*used < len && (p[*used] & 0xc0) == 0x80)
		(*used)++;
	return 0;
}

/* Escapes src into dst[0 .. n) (n > 0); returns the length written. Cuts at a whole
 * character or escape, ending in "..." when src does not fit. */
static size_t escape_into(char *dst, size_t n, const char *src, bool quote_bs)
{
	const unsigned char *p = (const unsigned char *)src;
	size_t o = 0, total = 0, used;
	char e[8];
	for (const unsigned char *q = p; *q; q += used) {
		size_t k = escape_at(q, quote_bs, &used, e);
		total += k ? k : used;
	}
	bool cut = total + 1 > n;
	size_t room = cut ? (n > 4 ? n - 4 : 0) : n - 1;
	while (*p) {
		size_t k = escape_at(p, quote_bs, &used, e);
		size_t len = k ? k : used;
		if (o + len > room)
			break;
		memcpy(dst + o, k ? e : (const char *)p, len);
		o += len;
		p += used;
	}
	if (cut && n > 4) {
		memcpy(dst + o, "...", 3);
		o += 3;
	}
	dst[o] = '\0';
	return o;
}

const char *log_escape(char *dst, size_t n, const char *src)
{
	escape_into(dst, n, src ? src : "", true);
	return dst;
}

void log_msg(enum log_level level, const char *fmt, ...)
{
	static const char *const tags[] = { "info", "error", "warning", "info", "debug" };
	/* sd-daemon(3) priorities: LOG_ERR 3, LOG_WARNING 4, LOG_INFO 6, LOG_DEBUG 7 */
	static const char *const prio[] = { "<6>", "<3>", "<4>", "<6>", "<7>" };
	if ((int)level > atomic_load(&threshold))
		return;
	char text[1024], line[1100];
	va_list ap;
	va_start(ap, fmt);
	int m = vsnprintf(text, sizeof text, fmt, ap);
	va_end(ap);
	if (m < 0)
		text[0] = '\0';
	int n = snprintf(line, sizeof line, "%s%s: ", atomic_load(&journal) ? prio[level] : "",
			 tags[level]);
	/* Whatever reached the format (a client's text included) stays on this one line. */
	size_t len = (size_t)n + escape_into(line + n, sizeof line - (size_t)n - 1, text, false);
	line[len++] = '\n';
	ssize_t w = write(STDERR_FILENO, line, len);
	(void)w; /* nowhere to report a failed write to stderr */
}
