/* fuzz_ini — libFuzzer target for the INI reader (common/ini.c) and the planet-file parser on
 * top of it (daemon/engine/planet.c: sections, [planet] keys, nodes and their parameters,
 * input slots, layers, cycles). Built and run by `make fuzz` (the engine and common compiled
 * with the fuzzer's sanitizers into build-fuzz/obj/).
 *
 * Properties checked, beyond "no crash, no leak, no undefined behaviour":
 *  - ini_parse either fails with a message or returns sections whose line numbers are
 *    increasing and within the text, keys non-empty and without surrounding blanks;
 *  - parsing is deterministic: the same text twice gives the same sections and entries;
 *  - the same text as a planet file (written to a memfd, loaded through /proc/self/fd) loads
 *    or fails with a "file:line: ..." message; a loaded planet has every layer's node in its
 *    node list and its nodes in topological order (each node after its inputs).
 * The node types are every type except `file` and `geoid` (they read files named in the
 * input: a fuzzer should not roam the file system).
 */
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "common/img.h"
#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static const struct node_type *const types[] = {
	&node_type_constant, &node_type_noise,	&node_type_color_filter, &node_type_height_filter,
	&node_type_ramp,     &node_type_blend,	&node_type_normal,	 &node_type_slope,
	&node_type_craters,  NULL,
};

static size_t count_lines(const uint8_t *d, size_t n)
{
	size_t k = 1;
	for (size_t i = 0; i < n; i++)
		k += d[i] == '\n';
	return k;
}

static void check_ini(const uint8_t *data, size_t size)
{
	struct ini_file *a = NULL, *b = NULL;
	char ea[256] = "", eb[256] = "";
	int ra = ini_parse("f.ini", (const char *)data, size, &a, ea);
	int rb = ini_parse("f.ini", (const char *)data, size, &b, eb);
	if (ra != rb || (ra && strcmp(ea, eb)))
		abort(); /* not deterministic */
	if (ra) {
		if (ra > 0 || !ea[0])
			abort(); /* a failure must say why */
		return;
	}
	size_t lines = count_lines(data, size);
	int last = -1;
	if (a->n != b->n)
		abort();
	for (size_t i = 0; i < a->n; i++) {
		const struct ini_section *s = &a->sections[i], *t = &b->sections[i];
		if (strcmp(s->name, t->name) || s->n != t->n || s->line != t->line)
			abort();
		if (s->line < 0 || (size_t)s->line > lines)
			abort();
		for (size_t j = 0; j < s->n; j++) {
			const struct ini_entry *e = &s->entries[j], *f = &t->entries[j];
			if (strcmp(e->key, f->key) || strcmp(e->value, f->value) || e->line != f->line)
				abort();
			if (e->line <= last || e->line < 1 || (size_t)e->line > lines)
				abort(); /* entries in text order, each on a line of the text */
			last = e->line;
			size_t kl = strlen(e->key);
			if (!kl || e->key[0] == ' ' || e->key[kl - 1] == ' ')
				abort();
		}
	}
	ini_free(a);
	ini_free(b);
}

static void check_planet(const uint8_t *data, size_t size)
{
	static struct img_cache *images; /* one for every input: creating one is slow */
	if (!images)
		images = img_cache_create(1);
	int fd = memfd_create("fuzz.ini", MFD_CLOEXEC);
	if (fd < 0)
		abort();
	if (size && write(fd, data, size) != (ssize_t)size)
		abort();
	char path[64];
	snprintf(path, sizeof path, "/proc/self/fd/%d", fd);
	struct planet *p = NULL;
	char err[256] = "";
	int rc = planet_load_shared(path, types, images, &p, err);
	close(fd);
	if (rc) {
		if (rc > 0 || !err[0])
			abort();
		return;
	}
	for (size_t i = 0; i < p->nnodes; i++)
		for (int s = 0; s < NODE_MAX_INPUTS; s++) {
			const struct node *in = p->nodes[i]->in[s];
			if (!in)
				continue;
			size_t k = 0;
			while (k < i && p->nodes[k] != in)
				k++;
			if (k == i)
				abort(); /* an input after its user, or not in the planet */
		}
	planet_unref(p);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (size > 64 << 10)
		return 0; /* planet files are small; keep each run fast */
	check_ini(data, size);
	check_planet(data, size);
	return 0;
}
