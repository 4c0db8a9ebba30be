/*
 * store.h -- luxradd's durable state in its data directory.
 *
 * Layout:
 *   <data_dir>/luxradd.db            SQLite (WAL): scenes and jobs metadata
 *   <data_dir>/store.lock            flock()ed while open: a second
 *                                    srv_store_open on the directory fails
 *   <data_dir>/scenes/<id>.bin       scene bytes as uploaded
 *   <data_dir>/results/<id>-<gen>.sol  a job's latest solution checkpoint
 *                                    (engine bytes, rad_solution_save);
 *                                    <gen> counts checkpoints, so a new
 *                                    one never overwrites the file the
 *                                    row names (see store_jobs.c)
 * Files are written atomically: a temporary in the same directory,
 * fsync, rename, fsync of the directory.  A row points to a file only
 * after the file is durable, so a crash leaves either the old or the new
 * state, never a row without its file.  Files without a row (a crash
 * between file and row) are removed by srv_store_open.
 *
 * The store is used from one thread at a time (the daemon serialises
 * calls with its own lock); it never calls back into the daemon.
 */
#ifndef LUXRAD_SRV_STORE_H
#define LUXRAD_SRV_STORE_H

#include <stddef.h>
#include <stdint.h>

typedef struct srv_store srv_store;

typedef struct srv_scene_row {
	uint64_t id;
	char name[256];
	uint64_t bytes; /* size of the uploaded file */
	double created; /* Unix time, seconds */
	char owner[64]; /* the user who uploaded it; "" = the local admin */
} srv_scene_row;

/* Job states as stored; the wire names are the lower-case words. */
typedef enum srv_job_state {
	SRV_JOB_QUEUED = 0,
	SRV_JOB_RUNNING,
	SRV_JOB_PAUSED,
	SRV_JOB_DONE,
	SRV_JOB_FAILED,
	SRV_JOB_CANCELLED,
	SRV_JOB_NSTATES
} srv_job_state;

const char *srv_job_state_name(srv_job_state s);

typedef struct srv_job_row {
	uint64_t id;
	uint64_t scene_id;
	char name[256];
	char *options_json; /* solver + options as given (malloc'ed) */
	char *target_json;  /* the current run request, "" if none */
	char *eps_log_json; /* [[iteration, eps], ...] changes (replay) */
	char *stats_json;   /* latest published statistics */
	srv_job_state state;
	uint32_t iterations; /* iterations done at the last checkpoint */
	int has_result;      /* a checkpoint exists (results/) */
	char error[512];     /* failed: why */
	double created, updated;
	char owner[64]; /* the user who created it; "" = the local admin */
} srv_job_row;

/* Free the malloc'ed strings of a row (not the row itself). */
void srv_job_row_clear(srv_job_row *r);

/*
 * Open (creating if needed) the data directory and its database; applies
 * the schema (versioned with PRAGMA user_version).  Returns NULL with msg
 * filled on failure (permissions, corrupt database...).
 */
srv_store *srv_store_open(const char *data_dir, char *msg, size_t msglen);
void srv_store_close(srv_store *st);

/*
 * What srv_store_open repaired ("" if nothing): orphan / temporary files
 * removed, checkpoints found missing (has_result cleared), scenes whose
 * bytes vanished (removed with their jobs).  For the daemon's log.
 */
const char *srv_store_repairs(const srv_store *st);

/* Each returns 0, or -1 with msg filled (the daemon reports "io"). */
int srv_store_scene_add(srv_store *st, const char *name, const char *owner,
                        const void *bytes, size_t len, uint64_t *id, char *msg,
                        size_t msglen);
/* Read a scene's bytes (malloc'ed, caller frees). */
int srv_store_scene_read(srv_store *st, uint64_t id, unsigned char **bytes,
                         size_t *len, char *msg, size_t msglen);
int srv_store_scene_delete(srv_store *st, uint64_t id, char *msg,
                           size_t msglen);
/*
 * Calls fn for every scene, in id order.  The row is borrowed for the
 * call.  fn may read (scene_read, job_result_read) but must not call a
 * *_list function again nor add, update or delete rows.
 */
int srv_store_scene_list(srv_store *st,
                         void (*fn)(void *ud, const srv_scene_row *r), void *ud,
                         char *msg, size_t msglen);

/* Insert a job (row->id is assigned). */
int srv_store_job_add(srv_store *st, srv_job_row *row, char *msg,
                      size_t msglen);
/* Update state, iterations, target, eps log, stats and error. */
int srv_store_job_update(srv_store *st, const srv_job_row *row, char *msg,
                         size_t msglen);
/*
 * Write a job's solution checkpoint atomically, then mark has_result and
 * iterations in the same transaction as the row update.
 */
int srv_store_job_checkpoint(srv_store *st, const srv_job_row *row,
                             const void *sol, size_t len, char *msg,
                             size_t msglen);
int srv_store_job_result_read(srv_store *st, uint64_t id, unsigned char **bytes,
                              size_t *len, char *msg, size_t msglen);
int srv_store_job_delete(srv_store *st, uint64_t id, char *msg, size_t msglen);
/* Calls fn for every job, in id order; same rules as scene_list (the
 * row's strings are freed when fn returns: copy what you keep). */
int srv_store_job_list(srv_store *st,
                       void (*fn)(void *ud, const srv_job_row *r), void *ud,
                       char *msg, size_t msglen);

/*
 * Sensors added over the protocol (sensor.add), kept with their job: a
 * job's deletion removes them.  pt is x y z nx ny nz.  Adding a name the
 * job already has fails.  list calls fn for every sensor, by job id and
 * then in the order they were added; fn must not write to the store.
 */
int srv_store_sensor_add(srv_store *st, uint64_t job, const char *name,
                         const double pt[6], char *msg, size_t msglen);
int srv_store_sensor_list(srv_store *st,
                          void (*fn)(void *ud, uint64_t job, const char *name,
                                     const double pt[6]),
                          void *ud, char *msg, size_t msglen);

#endif
