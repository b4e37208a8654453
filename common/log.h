/* log — one line per event on stderr (journald adds the time). Thread-safe: each line is
 * written with a single write(2). The threshold is process-wide state set once by main. When
 * stderr is the journal (log_detect_journal), each line starts with its syslog priority
 * ("<3>error: ...", sd-daemon(3)), which journald strips and records. A line never holds a
 * raw control character: log_msg escapes any that reach it (so text from a client cannot
 * forge a line or drive a terminal), and log_escape quotes a client's string unambiguously. */
#ifndef CLIPMAP_LOG_H
#define CLIPMAP_LOG_H
#include <stdbool.h>
#include <stddef.h>

enum log_level { LOG_DEFAULT = 0, LOG_ERROR, LOG_WARN, LOG_INFO, LOG_DEBUG };

/* Lines above `level` are dropped. Call from main before threads start. */
void log_set_level(enum log_level level);
/* Parses "error", "warn", "info", "debug"; returns 0 or -EINVAL. */
int log_parse_level(const char *s, enum log_level *out);
/* Whether stderr is the systemd journal ($JOURNAL_STREAM names it); from then on lines carry
 * priority prefixes, or stop carrying them when it is not. Call from main before threads. */
bool log_detect_journal(void);
void log_msg(enum log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Copies src (NULL: "") into dst[0 .. n) for a log line, NUL-terminated: a backslash becomes
 * "\\", \n \r \t stay readable as "\\n" "\\r" "\\t", any other byte below 0x20, DEL and
 * the UTF-8 C1 controls (U+0080..U+009F) become "\\xNN" (ESC: "\\x1b"). Text that does not
 * fit is cut at a whole escape and ends in "...". Returns dst (n > 0). Thread-safe. */
const char *log_escape(char *dst, size_t n, const char *src);

#endif
