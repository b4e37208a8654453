/* tilemem — the memory tile pixels live in: buffers of one size class (the tile's bytes,
 * rounded up to a page) carved from 32 MiB slabs, 2 MiB-aligned and asking for transparent
 * huge pages, and kept on a free list when a tile is freed instead of going back to the system.
 *
 * Why: on the virtual machines this project runs on (docs/ARCHITECTURE.md, "Memory"), the
 * first write to a fresh 4 KiB page costs ~11 µs (0.3-0.9 GB/s, even after MAP_POPULATE): a
 * fresh 256 KiB tile paid ~0.7 ms in page faults before a node wrote a texel, more than most
 * nodes take to fill it. A huge page faulted in by the write itself runs at ~12 GB/s, and a
 * recycled buffer costs nothing.
 *
 * What is kept: every buffer ever carved stays mapped. Free buffers beyond tilemem_keep's
 * bytes (and beyond what tilemem_prefault's bytes leave free) give their pages back
 * (MADV_DONTNEED, their slab off huge pages first) and are populated again
 * (MADV_POPULATE_WRITE) when reused, so a shrunken cache (a reload, a purge) does not keep
 * its peak resident.
 * Under AddressSanitizer the pool is bypassed (plain aligned allocations), so use-after-free
 * of tile memory is still caught.
 *
 * Thread-safe (one mutex; an alloc or free is a few dozen nanoseconds).
 */
#ifndef CLIPMAP_TILEMEM_H
#define CLIPMAP_TILEMEM_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* A buffer of at least n bytes, 64-byte aligned, contents undefined; aborts when no memory
 * can be had (as xmalloc). */
void *tilemem_alloc(size_t n);
/* Gives back a buffer from tilemem_alloc(n), with the same n. NULL is a no-op. */
void tilemem_free(void *p, size_t n);
/* Free bytes kept resident at most (default: unbounded); while the buffers in use and free
 * are within tilemem_prefault's bytes, freed ones stay resident whatever this says. */
void tilemem_keep(size_t bytes);

/* Maps pool buffers of n bytes (a tile's size, as tilemem_alloc) until the pool has `bytes` of
 * them mapped, one slab at a time, each slab's pages faulted in by this thread before its
 * buffers join the free ones; stops early when *stop becomes true (may be NULL). Meant for a
 * thread of its own at idle priority when the daemon starts: on this project's VMs the first
 * touch of memory the VM has not used lately runs at ~0.4 GB/s even on huge pages (its pages
 * are zeroed under the hypervisor), and a freshly restarted daemon serving stored tiles at
 * 1 900 tiles/s spent 17 % of both cores in those faults (bench_keepup "restarted", perf).
 * Free buffers then stay resident while in use + free is within `bytes` (tilemem_keep).
 * Returns the bytes faulted in. */
size_t tilemem_prefault(size_t n, size_t bytes, const _Atomic bool *stop);
/* Announces a tilemem_prefault of `bytes` about to start on another thread, before it is
 * created: prefault_left (tilemem_stats) counts it from now, not from when the thread first
 * runs (0 meanwhile would read as done). 0: none after all. */
void tilemem_prefault_expect(size_t bytes);

struct tilemem_stats {
	uint64_t mapped;   /* bytes of slabs mapped */
	uint64_t in_use;   /* bytes handed out and not yet given back */
	uint64_t free_warm; /* free bytes resident */
	uint64_t released; /* free bytes whose pages went back to the system */
	uint64_t prefault_left; /* bytes a running tilemem_prefault has still to map (0: none) */
};
void tilemem_stats(struct tilemem_stats *out);

#endif
