/* ini — see ini.h. A hand-written line parser: the format is tiny and the errors must carry
 * line numbers, which libinih only offers as a build-time option. */
#include "ini.h"

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "errbuf.h"
#include "xalloc.h"

static char *trim(char *s, char *end)
{
	while (s < end && isspace((unsigned char)*s))
		s++;
	while (end > s && isspace((unsigned char)end[-1]))
		end--;
	*end = '\0';
	return s;
}

/* Cuts a comment: a line starting with ';' or '#', or ';' after whitespace. '#' inside a line
 * is data, so colours can be written "#rrggbb". */
static char *strip_comment(char *s, char *end)
{
	char *p = s;
	while (p < end && isspace((unsigned char)*p))
		p++;
	if (p < end && (*p == ';' || *p == '#'))
		return p;
	for (; p < end; p++)
		if (*p == ';' && isspace((unsigned char)p[-1]))
			return p;
	return end;
}

static struct ini_section *add_section(struct ini_file *f, const char *name, int line)
{
	f->sections = xrealloc(f->sections, (f->n + 1) * sizeof *f->sections);
	struct ini_section *s = &f->sections[f->n++];
	s->name = xstrdup(name);
	s->line = line;
	s->entries = NULL;
	s->n = 0;
	return s;
}

static void fail(char *err, const char *path, int line, const char *msg)
{
	err_set(err, "%s:%d: %s", path, line, msg);
}

int ini_parse(const char *path, const char *text, size_t len, struct ini_file **out, char err[256])
{
	struct ini_file *f = xcalloc(1, sizeof *f);
	f->path = xstrdup(path);
	char *buf = xmalloc(len + 1);
	memcpy(buf, text, len);
	buf[len] = '\0';
	struct ini_section *cur = NULL;
	int line = 0, rc = 0;
	char *p = buf, *bufend = buf + len;
	while (p < bufend) {
		line++;
		char *nl = memchr(p, '\n', (size_t)(bufend - p));
		char *end = nl ? nl : bufend;
		if (memchr(p, '\0', (size_t)(end - p))) {
			fail(err, path, line, "NUL byte in text");
			rc = -EINVAL;
			goto done;
		}
		char *s = trim(p, strip_comment(p, end));
		p = nl ? nl + 1 : bufend;
		if (*s == '\0')
			continue;
		if (*s == '[') {
			char *close = strchr(s, ']');
			if (!close || close[1] != '\0') {
				fail(err, path, line, "section header must be \"[name]\"");
				rc = -EINVAL;
				goto done;
			}
			char *name = trim(s + 1, close);
			if (*name == '\0') {
				fail(err, path, line, "empty section name");
				rc = -EINVAL;
				goto done;
			}
			cur = add_section(f, name, line);
			continue;
		}
		char *eq = strchr(s, '=');
		if (!eq) {
			fail(err, path, line, "expected \"key = value\" or \"[section]\"");
			rc = -EINVAL;
			goto done;
		}
		char *key = trim(s, eq);
		char *value = trim(eq + 1, eq + 1 + strlen(eq + 1));
		if (*key == '\0') {
			fail(err, path, line, "missing key before '='");
			rc = -EINVAL;
			goto done;
		}
		if (!cur)
			cur = add_section(f, "", 0);
		cur->entries = xrealloc(cur->entries, (cur->n + 1) * sizeof *cur->entries);
		struct ini_entry *e = &cur->entries[cur->n++];
		e->key = xstrdup(key);
		e->value = xstrdup(value);
		e->line = line;
		e->used = false;
	}
done:
	free(buf);
	if (rc) {
		ini_free(f);
		return rc;
	}
	*out = f;
	return 0;
}

int ini_load(const char *path, struct ini_file **out, char err[256])
{
	FILE *fp = fopen(path, "rb");
	if (!fp) {
		int e = errno;
		err_set(err, "%s: %s", path, strerror(e));
		return -e;
	}
	size_t cap = 4096, len = 0;
	char *text = xmalloc(cap);
	size_t got;
	while ((got = fread(text + len, 1, cap - len, fp)) > 0) {
		len += got;
		if (len == cap)
			text = xrealloc(text, cap *= 2);
		if (len > (64u << 20)) {
			fclose(fp);
			free(text);
			err_set(err, "%s: larger than 64 MiB: not a config file", path);
			return -EFBIG;
		}
	}
	int rerr = ferror(fp) ? errno : 0;
	fclose(fp);
	if (rerr) {
		free(text);
		err_set(err, "%s: %s", path, strerror(rerr));
		return -rerr;
	}
	int rc = ini_parse(path, text, len, out, err);
	free(text);
	return rc;
}

void ini_free(struct ini_file *f)
{
	if (!f)
		return;
	for (size_t i = 0; i < f->n; i++) {
		struct ini_section *s = &f->sections[i];
		for (size_t j = 0; j < s->n; j++) {
			free(s->entries[j].key);
			free(s->entries[j].value);
		}
		free(s->entries);
		free(s->name);
	}
	free(f->sections);
	free(f->path);
	free(f);
}

struct ini_entry *ini_find(const struct ini_section *s, const char *key)
{
	for (size_t i = s->n; i-- > 0;)
		if (strcmp(s->entries[i].key, key) == 0)
			return &s->entries[i];
	return NULL;
}
