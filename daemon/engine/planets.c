/* planets — see planets.h. */
#include "planets.h"

#include <dirent.h>
#include <errno.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/img.h"
#include "common/xalloc.h"

static int cmp_str(const void *a, const void *b)
{
	return strcmp(*(char *const *)a, *(char *const *)b);
}

static int cmp_planet(const void *a, const void *b)
{
	return strcmp((*(struct planet *const *)a)->name, (*(struct planet *const *)b)->name);
}

static void set_free(struct planet_set *s)
{
	for (size_t i = 0; i < s->n; i++)
		planet_unref(s->planets[i]);
	free(s->planets);
	for (size_t i = 0; i < s->nskipped; i++)
		free(s->skipped[i]);
	free(s->skipped);
	img_cache_unref(s->images);
	free(s);
}

/* Keeps the error of a planet file left out of the set. */
static void skip_file(struct planet_set *s, const char *err)
{
	s->skipped = xrealloc(s->skipped, (s->nskipped + 1) * sizeof *s->skipped);
	s->skipped[s->nskipped++] = xstrdup(err);
}

/* planet_set_load (each false) or planet_set_load_each (each true). */
static int load_set(const char *dir, uint64_t generation, struct img_cache *images, bool each,
		    struct planet_set **out, char err[256])
{
	*out = NULL;
	DIR *d = opendir(dir);
	if (!d) {
		int e = -errno;
		err_set(err, "%s: %s", dir, strerror(-e));
		return e;
	}
	char **names = NULL;
	size_t nn = 0;
	struct dirent *de;
	while ((de = readdir(d))) {
		size_t l = strlen(de->d_name);
		if (de->d_name[0] == '.' || l < 5 || strcmp(de->d_name + l - 4, ".ini") != 0)
			continue;
		names = xrealloc(names, (nn + 1) * sizeof *names);
		names[nn++] = xstrdup(de->d_name);
	}
	closedir(d);
	if (nn) /* qsort's base must not be NULL, even for no elements */
		qsort(names, nn, sizeof *names, cmp_str);

	struct planet_set *s = xcalloc(1, sizeof *s);
	atomic_init(&s->refs, 1);
	s->generation = generation;
	s->planets = xcalloc(nn ? nn : 1, sizeof *s->planets);
	s->images = images ? img_cache_ref(images) : img_cache_create(PLANET_IMAGE_CACHE_MB);
	int rc = 0;
	if (!s->images) {
		err_set(err, "%s: cannot create an image cache", dir);
		rc = -ENOMEM;
	}
	for (size_t i = 0; i < nn && !rc; i++) {
		size_t pl = strlen(dir) + strlen(names[i]) + 2;
		char *path = xmalloc(pl);
		snprintf(path, pl, "%s/%s", dir, names[i]);
		struct planet *p = NULL;
		rc = planet_load_shared(path, NULL, s->images, &p, err);
		free(path);
		if (rc == 0 && planet_set_find(s, p->name)) {
			err_set(err, "%s: planet \"%s\" is defined twice in %s", p->path, p->name,
				dir);
			planet_unref(p);
			rc = -EINVAL;
		}
		if (rc && each && rc != -ENOMEM) {
			skip_file(s, err);
			rc = 0;
			continue;
		}
		if (rc)
			break;
		s->planets[s->n++] = p;
		qsort(s->planets, s->n, sizeof *s->planets, cmp_planet);
	}
	for (size_t i = 0; i < nn; i++)
		free(names[i]);
	free(names);
	if (rc == 0 && s->n == 0 && s->nskipped) {
		err_set(err, "%s (and no other planet loaded)", s->skipped[0]);
		rc = -EINVAL;
	}
	if (rc) {
		set_free(s);
		return rc;
	}
	*out = s;
	return 0;
}

int planet_set_load(const char *dir, uint64_t generation, struct img_cache *images,
		    struct planet_set **out, char err[256])
{
	return load_set(dir, generation, images, false, out, err);
}

int planet_set_load_each(const char *dir, uint64_t generation, struct img_cache *images,
			 struct planet_set **out, char err[256])
{
	return load_set(dir, generation, images, true, out, err);
}

struct planet_set *planet_set_ref(struct planet_set *s)
{
	atomic_fetch_add(&s->refs, 1);
	return s;
}

void planet_set_unref(struct planet_set *s)
{
	if (s && atomic_fetch_sub(&s->refs, 1) == 1)
		set_free(s);
}

struct planet *planet_set_find(const struct planet_set *s, const char *name)
{
	size_t lo = 0, hi = s->n;
	while (lo < hi) {
		size_t mid = (lo + hi) / 2;
		int c = strcmp(name, s->planets[mid]->name);
		if (c == 0)
			return s->planets[mid];
		if (c < 0)
			hi = mid;
		else
			lo = mid + 1;
	}
	return NULL;
}

int planet_set_has_node(const struct planet_set *s, uint64_t h)
{
	for (size_t i = 0; i < s->n; i++)
		for (size_t j = 0; j < s->planets[i]->nnodes; j++)
			if (s->planets[i]->nodes[j]->hash == h)
				return 1;
	return 0;
}
