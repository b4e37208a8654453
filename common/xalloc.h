/* xalloc — the one allocation family: failure aborts with a message (STYLE: "Allocation
 * failure aborts through one xmalloc family"). Thread-safe; every function returns owned
 * memory that the caller frees with free() (xaligned_alloc too). */
#ifndef CLIPMAP_XALLOC_H
#define CLIPMAP_XALLOC_H
#include <stddef.h>

void *xmalloc(size_t n);
void *xcalloc(size_t count, size_t size);
void *xrealloc(void *p, size_t n);
char *xstrdup(const char *s);
/* Memory aligned to `align` (a power of two ≥ sizeof(void*)), size rounded up to it. */
void *xaligned_alloc(size_t align, size_t n);
/* Reports that n bytes could not be had and aborts (for allocators built on these). */
_Noreturn void xalloc_fail(size_t n);

#endif
