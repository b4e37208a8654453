/* ini — a small INI reader that keeps line numbers, so every config error can name
 * file:line: key. Syntax: "[section name]" headers, "key = value" lines; a line starting with
 * ';' or '#' is a comment, and so is the rest of a line from a ';' that follows whitespace
 * ('#' inside a line is data: colours are "#rrggbb"); surrounding whitespace is trimmed.
 * Keys outside any section belong to a section named "" (line 0).
 *
 * Ownership: ini_load/ini_parse return an owned struct ini_file freed with ini_free; all
 * strings inside belong to it. Not thread-safe for concurrent mutation (the `used` flags);
 * read-only use from many threads is fine.
 */
#ifndef CLIPMAP_INI_H
#define CLIPMAP_INI_H
#include <stdbool.h>
#include <stddef.h>

struct ini_entry {
	char *key;
	char *value;
	int line;
	bool used; /* set by whoever consumes the entry, to report unknown keys */
};

struct ini_section {
	char *name; /* as written between the brackets, trimmed */
	int line;
	struct ini_entry *entries;
	size_t n;
};

struct ini_file {
	char *path;
	struct ini_section *sections;
	size_t n;
};

/* Reads and parses a file. Returns 0, or -errno with err = "path: strerror" or
 * "path:line: message" for syntax errors (err may be NULL). */
int ini_load(const char *path, struct ini_file **out, char err[256]);
/* Parses text; `path` is used only in messages. */
int ini_parse(const char *path, const char *text, size_t len, struct ini_file **out, char err[256]);
void ini_free(struct ini_file *f);
/* The last entry named key in the section, or NULL (borrowed). */
struct ini_entry *ini_find(const struct ini_section *s, const char *key);

#endif
