/* proc_rss — a process's resident memory (VmRSS of /proc/PID/status), for tests that bound a
 * daemon's memory or check that memory was faulted in. Test-only code. */
#ifndef CLIPMAP_TEST_PROC_RSS_H
#define CLIPMAP_TEST_PROC_RSS_H
#include <stdint.h>
#include <sys/types.h>

/* VmRSS of process pid (0: this one) in KiB; 0 when it cannot be read. */
uint64_t proc_rss_kb(pid_t pid);

#endif
