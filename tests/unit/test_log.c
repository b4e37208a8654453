/* log: lines on stderr as "error: ..."; when stderr is the systemd journal ($JOURNAL_STREAM
 * names its device and inode) each line starts with its syslog priority (<3> error, <4>
 * warning, <6> info, <7> debug) for journald to record; a JOURNAL_STREAM naming another stream
 * (stderr redirected since) changes nothing. Text from clients cannot forge a line or reach a
 * terminal: log_escape quotes control characters, and log_msg escapes any that reach it.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmocka.h>

#include "common/log.h"

/* Runs the four log lines with stderr on a temporary file, JOURNAL_STREAM naming that file
 * (same) or something else; returns what was written (static). */
static const char *capture(int same)
{
	static char buf[1024];
	char path[] = "/tmp/test_log.XXXXXX";
	int fd = mkstemp(path);
	assert_true(fd >= 0);
	unlink(path);
	int saved = dup(STDERR_FILENO);
	assert_true(saved >= 0);
	assert_int_equal(dup2(fd, STDERR_FILENO), STDERR_FILENO);
	struct stat st;
	assert_int_equal(fstat(fd, &st), 0);
	char js[64];
	snprintf(js, sizeof js, "%llu:%llu", (unsigned long long)st.st_dev,
		 (unsigned long long)st.st_ino + (same ? 0 : 1));
	setenv("JOURNAL_STREAM", js, 1);
	int on = log_detect_journal();
	log_set_level(LOG_DEBUG);
	log_msg(LOG_ERROR, "e %d", 1);
	log_msg(LOG_WARN, "w");
	log_msg(LOG_INFO, "i");
	log_msg(LOG_DEBUG, "d");
	dup2(saved, STDERR_FILENO);
	close(saved);
	unsetenv("JOURNAL_STREAM");
	log_detect_journal();
	assert_int_equal(on, same);
	ssize_t n = pread(fd, buf, sizeof buf - 1, 0);
	close(fd);
	assert_true(n > 0);
	buf[n] = '\0';
	return buf;
}

static void test_journal_priorities(void **state)
{
	(void)state;
	assert_string_equal(capture(1), "<3>error: e 1\n<4>warning: w\n<6>info: i\n<7>debug: d\n");
}

static void test_plain_when_not_the_journal(void **state)
{
	(void)state;
	assert_string_equal(capture(0), "error: e 1\nwarning: w\ninfo: i\ndebug: d\n");
}

static void test_escape(void **state)
{
	(void)state;
	char b[64];
	assert_string_equal(log_escape(b, sizeof b, "ok\nerror: FORGED"), "ok\\nerror: FORGED");
	assert_string_equal(log_escape(b, sizeof b, "\x1b[31mred\r\t\\"),
			    "\\x1b[31mred\\r\\t\\\\");
	assert_string_equal(log_escape(b, sizeof b, "del\x7f c1\xc2\x9b caf\xc3\xa9"),
			    "del\\x7f c1\\x9b caf\xc3\xa9");
	assert_string_equal(log_escape(b, sizeof b, NULL), "");
	/* cut at a whole escape or character, marked */
	char s8[8];
	assert_string_equal(log_escape(s8, sizeof s8, "abc\ndefgh"), "abc...");
	assert_string_equal(log_escape(s8, sizeof s8, "a\xc3\xa9\xc3\xa9\xc3\xa9\xc3\xa9"),
			    "a\xc3\xa9...");
	assert_string_equal(log_escape(s8, sizeof s8, "1234567"), "1234567");
}

/* A format argument holding a newline or an escape sequence stays on its one line. */
static void test_msg_never_forges_a_line(void **state)
{
	(void)state;
	char path[] = "/tmp/test_log.XXXXXX";
	int fd = mkstemp(path);
	assert_true(fd >= 0);
	unlink(path);
	int saved = dup(STDERR_FILENO);
	assert_int_equal(dup2(fd, STDERR_FILENO), STDERR_FILENO);
	log_set_level(LOG_INFO);
	log_msg(LOG_INFO, "name %s", "ok\nerror: FORGED\x1b]0;x\x07");
	dup2(saved, STDERR_FILENO);
	close(saved);
	char buf[256];
	ssize_t n = pread(fd, buf, sizeof buf - 1, 0);
	close(fd);
	assert_true(n > 0);
	buf[n] = '\0';
	assert_string_equal(buf, "info: name ok\\nerror: FORGED\\x1b]0;x\\x07\n");
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_journal_priorities),
		cmocka_unit_test(test_plain_when_not_the_journal),
		cmocka_unit_test(test_escape),
		cmocka_unit_test(test_msg_never_forges_a_line),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
