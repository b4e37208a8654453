/* log — see log.h. The threshold is an atomic so reading it from any thread is race-free. */
#include "log.h"

#include <errno.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

static atomic_int threshold = LOG_INFO;

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

void log_msg(enum log_level level, const char *fmt, ...)
{
	static const char *const tags[] = { "info", "error", "warning", "info", "debug" };
	if ((int)level > atomic_load(&threshold))
		return;
	char line[1024];
	int n = snprintf(line, sizeof line, "%s: ", tags[level]);
	va_list ap;
	va_start(ap, fmt);
	int m = vsnprintf(line + n, sizeof line - (size_t)n - 1, fmt, ap);
	va_end(ap);
	size_t len = (size_t)n + (m < 0 ? 0 : (size_t)m);
	if (len > sizeof line - 2)
		len = sizeof line - 2;
	line[len++] = '\n';
	ssize_t w = write(STDERR_FILENO, line, len);
	(void)w; /* nowhere to report a failed write to stderr */
}
