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

void log_msg(enum log_level level, const char *fmt, ...)
{
	static const char *const tags[] = { "info", "error", "warning", "info", "debug" };
	/* sd-daemon(3) priorities: LOG_ERR 3, LOG_WARNING 4, LOG_INFO 6, LOG_DEBUG 7 */
	static const char *const prio[] = { "<6>", "<3>", "<4>", "<6>", "<7>" };
	if ((int)level > atomic_load(&threshold))
		return;
	char line[1024];
	int n = snprintf(line, sizeof line, "%s%s: ", atomic_load(&journal) ? prio[level] : "",
			 tags[level]);
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
