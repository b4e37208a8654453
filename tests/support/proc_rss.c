/* proc_rss — see proc_rss.h. */
#include "support/proc_rss.h"

#include <inttypes.h>
#include <stdio.h>

uint64_t proc_rss_kb(pid_t pid)
{
	char path[64], line[256];
	if (pid)
		snprintf(path, sizeof path, "/proc/%d/status", (int)pid);
	else
		snprintf(path, sizeof path, "/proc/self/status");
	FILE *f = fopen(path, "r");
	uint64_t kb = 0;
	while (f && fgets(line, sizeof line, f))
		if (sscanf(line, "VmRSS: %" SCNu64 " kB", &kb) == 1)
			break;
	if (f)
		fclose(f);
	return kb;
}
