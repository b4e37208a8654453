/* test_ini — the INI reader's syntax edge cases: comments, whitespace, bad lines and headers
 * with their line numbers, duplicate keys, empty input, reading from a file. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/ini.h"

static struct ini_file *parse_ok(const char *text)
{
	struct ini_file *f = NULL;
	char err[256] = "";
	int rc = ini_parse("t.ini", text, strlen(text), &f, err);
	if (rc)
		fail_msg("ini_parse: %d %s", rc, err);
	return f;
}

static void parse_fails(const char *text, const char *expect)
{
	struct ini_file *f = NULL;
	char err[256] = "";
	int rc = ini_parse("t.ini", text, strlen(text), &f, err);
	assert_int_equal(rc, -EINVAL);
	if (!strstr(err, expect))
		fail_msg("error \"%s\" lacks \"%s\"", err, expect);
}

static const char *value(const struct ini_section *s, const char *key)
{
	struct ini_entry *e = ini_find(s, key);
	return e ? e->value : NULL;
}

static void sections_and_line_numbers(void **state)
{
	(void)state;
	struct ini_file *f = parse_ok("; leading comment\n"
				      "\n"
				      "[planet]\n"
				      "name = earth\n"
				      "\n"
				      "[node  base heights ]\n"
				      "type = constant\n");
	assert_int_equal(f->n, 2);
	assert_string_equal(f->sections[0].name, "planet");
	assert_int_equal(f->sections[0].line, 3);
	assert_int_equal(f->sections[0].n, 1);
	assert_int_equal(f->sections[0].entries[0].line, 4);
	assert_false(f->sections[0].entries[0].used);
	/* Outer whitespace is trimmed; inner whitespace is kept as written. */
	assert_string_equal(f->sections[1].name, "node  base heights");
	assert_int_equal(f->sections[1].line, 6);
	assert_string_equal(value(&f->sections[1], "type"), "constant");
	assert_int_equal(f->sections[1].entries[0].line, 7);
	ini_free(f);
}

static void comments(void **state)
{
	(void)state;
	struct ini_file *f = parse_ok("[s]\n"
				      "# hash comment\n"
				      "   ; indented comment\n"
				      "a = 1 ; trailing comment\n"
				      "b = 2\t; trailing comment after a tab\n"
				      "col = #102030\n"
				      "c = x;y#z\n"
				      "url = http://example.com/#frag\n"
				      "[t] ; comment after a header\n"
				      "d = 4\n");
	assert_int_equal(f->n, 2);
	const struct ini_section *s = &f->sections[0];
	assert_int_equal(s->n, 5);
	assert_string_equal(value(s, "a"), "1");
	assert_string_equal(value(s, "b"), "2");
	/* '#' inside a line is data (colours); ';' only comments after whitespace. */
	assert_string_equal(value(s, "col"), "#102030");
	assert_string_equal(value(s, "c"), "x;y#z");
	assert_string_equal(value(s, "url"), "http://example.com/#frag");
	assert_string_equal(f->sections[1].name, "t");
	assert_string_equal(value(&f->sections[1], "d"), "4");
	ini_free(f);
}

static void whitespace_and_equals(void **state)
{
	(void)state;
	struct ini_file *f = parse_ok("\t[ s ]\t\r\n"
				      "   key   =   value with  spaces   \r\n"
				      "empty =\n"
				      "expr = a = b\n"
				      "k2=v2");
	const struct ini_section *s = &f->sections[0];
	assert_string_equal(s->name, "s");
	assert_string_equal(value(s, "key"), "value with  spaces");
	assert_string_equal(value(s, "empty"), "");
	/* The first '=' separates key from value. */
	assert_string_equal(value(s, "expr"), "a = b");
	/* The last line needs no newline. */
	assert_string_equal(value(s, "k2"), "v2");
	assert_int_equal(ini_find(s, "k2")->line, 5);
	assert_null(ini_find(s, "missing"));
	assert_null(ini_find(s, "KEY")); /* keys are case-sensitive */
	ini_free(f);
}

static void keys_outside_sections(void **state)
{
	(void)state;
	struct ini_file *f = parse_ok("a = 1\n[s]\nb = 2\n");
	assert_int_equal(f->n, 2);
	assert_string_equal(f->sections[0].name, "");
	assert_int_equal(f->sections[0].line, 0);
	assert_string_equal(value(&f->sections[0], "a"), "1");
	ini_free(f);
}

static void last_duplicate_wins(void **state)
{
	(void)state;
	struct ini_file *f = parse_ok("[s]\nk = first\nother = x\nk = second\n[s]\nk = third\n");
	/* Repeated sections stay separate, in file order. */
	assert_int_equal(f->n, 2);
	const struct ini_section *s = &f->sections[0];
	assert_int_equal(s->n, 3);
	assert_string_equal(value(s, "k"), "second");
	assert_int_equal(ini_find(s, "k")->line, 4);
	assert_string_equal(value(&f->sections[1], "k"), "third");
	ini_free(f);
}

static void empty_inputs(void **state)
{
	(void)state;
	struct ini_file *f = parse_ok("");
	assert_int_equal(f->n, 0);
	ini_free(f);
	f = parse_ok("\n\n   \n; only a comment\n# and another\n");
	assert_int_equal(f->n, 0);
	ini_free(f);
	f = parse_ok("[empty]\n");
	assert_int_equal(f->n, 1);
	assert_int_equal(f->sections[0].n, 0);
	ini_free(f);
	ini_free(NULL);
}

static void syntax_errors(void **state)
{
	(void)state;
	parse_fails("[s]\na = 1\nno equals sign here\n", "t.ini:3: expected \"key = value\"");
	parse_fails("[s]\n= value\n", "t.ini:2: missing key before '='");
	parse_fails("\n[unclosed\n", "t.ini:2: section header must be \"[name]\"");
	parse_fails("[s] trailing\n", "t.ini:1: section header must be \"[name]\"");
	parse_fails("[s]\n[]\n", "t.ini:2: empty section name");
	parse_fails("[s]\n\n\n[   ]\n", "t.ini:4: empty section name");
	/* CRLF line endings count lines the same way. */
	parse_fails("[s]\r\na = 1\r\nbad\r\n", "t.ini:3: expected");
	/* A NUL byte inside the text is refused. */
	struct ini_file *f = NULL;
	char err[256] = "";
	static const char nul[] = "[s]\na = 1\nb = x\0y\n";
	assert_int_equal(ini_parse("t.ini", nul, sizeof nul - 1, &f, err), -EINVAL);
	assert_non_null(strstr(err, "t.ini:3: NUL byte"));
	/* err may be NULL. */
	assert_int_equal(ini_parse("t.ini", "oops\n", 5, &f, NULL), -EINVAL);
}

static void load_file(void **state)
{
	(void)state;
	char dir[] = "/tmp/test_ini.XXXXXX";
	assert_non_null(mkdtemp(dir));
	char path[300];
	snprintf(path, sizeof path, "%s/x.ini", dir);
	FILE *fp = fopen(path, "w");
	assert_non_null(fp);
	/* Longer than the reader's first 4 KiB buffer. */
	fputs("[big]\n", fp);
	for (int i = 0; i < 500; i++)
		fprintf(fp, "key%d = value number %d\n", i, i);
	assert_int_equal(fclose(fp), 0);

	struct ini_file *f = NULL;
	char err[256] = "";
	assert_int_equal(ini_load(path, &f, err), 0);
	assert_string_equal(f->path, path);
	assert_int_equal(f->n, 1);
	assert_int_equal(f->sections[0].n, 500);
	assert_string_equal(value(&f->sections[0], "key499"), "value number 499");
	assert_int_equal(ini_find(&f->sections[0], "key499")->line, 501);
	ini_free(f);

	assert_int_equal(unlink(path), 0);
	f = NULL;
	assert_int_equal(ini_load(path, &f, err), -ENOENT);
	assert_null(f);
	char expect[400];
	snprintf(expect, sizeof expect, "%s: %s", path, strerror(ENOENT));
	assert_string_equal(err, expect);
	assert_int_equal(rmdir(dir), 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(sections_and_line_numbers),
		cmocka_unit_test(comments),
		cmocka_unit_test(whitespace_and_equals),
		cmocka_unit_test(keys_outside_sections),
		cmocka_unit_test(last_duplicate_wins),
		cmocka_unit_test(empty_inputs),
		cmocka_unit_test(syntax_errors),
		cmocka_unit_test(load_file),
	};
	return cmocka_run_group_tests_name("ini", tests, NULL, NULL);
}
