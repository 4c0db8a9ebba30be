/*
 * registry.c -- the scene and job registries' lookups, and what a job's
 * state says.  The lists themselves are the srv's (I/O thread); adding
 * and removing, which tell the observers, are in scenes.c and job.c.
 */
#include "core.h"

srv_scene *srv_scene_find(srv *s, uint64_t id)
{
	for (srv_scene *sc = s->scenes; sc; sc = sc->next)
		if (sc->id == id)
			return sc;
	return NULL;
}

srv_job *srv_job_find(srv *s, uint64_t id)
{
	for (srv_job *j = s->jobs; j; j = j->next)
		if (j->id == id)
			return j;
	return NULL;
}

int srv_job_terminal(srv_job_state st)
{
	return st == SRV_JOB_DONE || st == SRV_JOB_FAILED ||
	       st == SRV_JOB_CANCELLED;
}
