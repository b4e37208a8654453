/* node_types — the built-in registry: a static const table, looked up by name. */
#include "node_types.h"

#include <stddef.h>
#include <string.h>

static const struct node_type *const all_types[] = {
	&node_type_constant,	 &node_type_noise, &node_type_color_filter,
	&node_type_height_filter, &node_type_ramp,  &node_type_blend,
	&node_type_normal,	 &node_type_slope, &node_type_file, &node_type_geoid,
	&node_type_craters,	 &node_type_vector, &node_type_color_mask, &node_type_open_sea,
	&node_type_cells,
	NULL,
};

const struct node_type *node_types_find_in(const struct node_type *const *types, const char *name)
{
	for (size_t i = 0; types[i]; i++)
		if (strcmp(types[i]->name, name) == 0)
			return types[i];
	return NULL;
}

const struct node_type *node_type_find(const char *name)
{
	return node_types_find_in(all_types, name);
}

const struct node_type *const *node_types_all(void)
{
	return all_types;
}
