/*
 * memory.c -- the daemon's memory limit: the engine's process-wide limit
 * (rad_mem_set_limit) set from memory_limit, the refusal of new work
 * while it is reached, and the words that say so.
 *
 * The engine counts every byte it holds, in every scene, solver and
 * solution, and refuses an allocation that would pass the limit as if
 * the allocator were out of memory: the upload or job that asked gets
 * nomem and fails alone, before the kernel's OOM killer would take the
 * whole daemon.  What the daemon itself holds beside the engine
 * (connection buffers, JSON) is bounded by the per-connection limits and
 * is not counted here.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "core.h"
#include "log.h"

/* The cgroup v2 memory.max of this process; 0 when none or "max". */
static int64_t cgroup_limit(void)
{
	char line[4096], path[4400];
	FILE *f = fopen("/proc/self/cgroup", "r");
	int64_t lim = 0;
	if (!f)
		return 0;
	while (fgets(line, sizeof(line), f)) {
		if (strncmp(line, "0::", 3) != 0)
			continue;
		line[strcspn(line, "\n")] = '\0';
		snprintf(path, sizeof(path), "/sys/fs/cgroup%s/memory.max",
		         line + 3);
		FILE *m = fopen(path, "r");
		char v[64];
		if (m && fgets(v, sizeof(v), m) && strncmp(v, "max", 3) != 0)
			lim = strtoll(v, NULL, 10);
		if (m)
			fclose(m);
	}
	fclose(f);
	return lim > 0 ? lim : 0;
}

void srv_memory_limit_apply(srv *s)
{
	int64_t lim = (int64_t)s->cfg.memory_limit;
	const char *how = "memory_limit";
	if (lim == 0) {
		long pages = sysconf(_SC_PHYS_PAGES),
		     size = sysconf(_SC_PAGESIZE);
		int64_t ram = pages > 0 && size > 0 ? (int64_t)pages * size : 0;
		int64_t cg = cgroup_limit();
		int64_t base = cg > 0 && (ram == 0 || cg < ram) ? cg : ram;
		how = cg > 0 && base == cg ? "3/4 of the cgroup's memory.max"
		                           : "3/4 of the machine's memory";
		lim = base / 4 * 3;
	}
	if (lim != s->mem_limit)
		srv_info("memory limit %.1f MiB (%s)", (double)lim / 1048576.0,
		         how);
	s->mem_limit = lim;
	rad_mem_set_limit(lim);
}

int srv_memory_full(const srv *s, char *why, size_t len)
{
	int64_t held = rad_mem_limit_held(); /* solver processes too */
	if (s->mem_limit <= 0 || held < s->mem_limit)
		return 0;
	if (why)
		snprintf(why, len,
		         "the daemon's memory limit is reached: scenes, jobs "
		         "(their solver processes included) and "
		         "solutions hold %.1f MiB of %.1f MiB (memory_limit); "
		         "delete "
		         "some or raise the limit",
		         (double)held / 1048576.0,
		         (double)s->mem_limit / 1048576.0);
	return 1;
}

void srv_memory_note_limit(int64_t limit, uint64_t refusals_before, char *msg,
                           size_t len)
{
	if (limit <= 0 || rad_mem_limit_refusals() == refusals_before)
		return;
	size_t n = strlen(msg);
	if (n + 1 < len)
		snprintf(msg + n, len - n,
		         " (the daemon's memory limit, %.1f MiB, would have "
		         "been passed; memory_limit)",
		         (double)limit / 1048576.0);
}

void srv_memory_note(const srv *s, uint64_t refusals_before, char *msg,
                     size_t len)
{
	srv_memory_note_limit(s->mem_limit, refusals_before, msg, len);
}
