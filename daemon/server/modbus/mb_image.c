/*
 * mb_image.c -- the Modbus register image: publication from any thread,
 * snapshots for the Modbus thread, and the job and sensor slot tables.
 *
 * DESIGN
 * The image is the registers themselves (MB_ADDR_END words, as a client
 * reads them), written at publication, so a read is one bounds check and
 * one memcpy under the mutex; only the uptime is computed at read time.
 * Encoding at publication also means a request never sees half of an
 * update: publication and reads hold the same mutex for their whole
 * duration (the only lock here, a leaf: nothing is called while held).
 *
 * Jobs and sensors the daemon published are kept in arrays sorted by key
 * (job id; job id then name), slotted or not, with their last values:
 * when a slot frees, the first unslotted entry in key order takes it and
 * its registers are written from those values at once, so a promoted
 * done job shows its final numbers, not sentinels.  Lookups are binary
 * searches; insertion and removal move the tail (jobs are created and
 * deleted far less often than they are published).
 */
#include "mb_image.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct jent {
	uint64_t id;
	int slot; /* -1 = unslotted */
	mb_job_vals v;
} jent;

typedef struct sent {
	uint64_t job;
	char name[MB_SENSOR_NAME_MAX];
	int slot; /* -1 = unslotted */
	double lux;
	uint32_t iteration;
} sent;

struct mb_image {
	pthread_mutex_t mu; /* guards everything below but the immutables */
	/* immutable after mb_image_new */
	mb_word_order wo;
	unsigned job_slots, sensor_slots;
	double lux_scale;
	/* guarded by mu */
	double start_mono_s; /* NaN until the daemon publishes it */
	jent *jobs;          /* sorted by id */
	size_t njobs, jcap;
	sent *sens; /* sorted by (job, name) */
	size_t nsens, scap;
	size_t jobs_unslotted, sensors_unslotted;
	uint32_t by_state[MB_JOB_NSTATES];  /* published jobs by state */
	uint8_t job_used[MB_JOB_SLOTS_MAX]; /* slot taken */
	uint8_t sens_used[MB_SENSOR_SLOTS_MAX];
	uint16_t reg[MB_ADDR_END]; /* the registers, as clients read them */
};

/* ------------------------------------------------------------- encoding */

static void put_u16(mb_image *im, unsigned addr, uint16_t v)
{
	im->reg[addr] = v;
}

static void put_u32(mb_image *im, unsigned addr, uint32_t v)
{
	mb_put_u32(&im->reg[addr], v, im->wo);
}

static void put_f32(mb_image *im, unsigned addr, double v)
{
	mb_put_f32(&im->reg[addr], (float)v, im->wo);
}

static uint32_t id32(uint64_t id)
{
	return id > 0 && id < MB_U32_NA ? (uint32_t)id : MB_U32_NA;
}

static uint32_t count32(int64_t v)
{
	return v < 0 ? MB_U32_NA : mb_u32_of((uint64_t)v);
}

static unsigned job_addr(int slot, unsigned off)
{
	return MB_JOB_BASE + MB_JOB_STRIDE * (unsigned)slot + off;
}

static unsigned sens_addr(int slot, unsigned off)
{
	return MB_SENSOR_BASE + MB_SENSOR_STRIDE * (unsigned)slot + off;
}

static void job_write(mb_image *im, int slot, const mb_job_vals *v)
{
	put_u32(im, job_addr(slot, MB_J_JOB_ID), id32(v->job_id));
	put_u16(im, job_addr(slot, MB_J_STATE), (uint16_t)v->state);
	put_u16(im, job_addr(slot, MB_J_PROGRESS), mb_permille_of(v->progress));
	put_u32(im, job_addr(slot, MB_J_ITERATION), count32(v->iteration));
	put_f32(im, job_addr(slot, MB_J_RESIDUAL), v->residual);
	put_f32(im, job_addr(slot, MB_J_ERROR_ESTIMATE), v->error_estimate);
	put_u32(im, job_addr(slot, MB_J_LINKS), count32(v->links));
	put_u32(im, job_addr(slot, MB_J_MEMORY),
	        mb_kib_of_bytes(v->memory_bytes));
	put_u32(im, job_addr(slot, MB_J_ELAPSED),
	        mb_u32_of_double(v->elapsed_s));
	put_u32(im, job_addr(slot, MB_J_ETA), mb_u32_of_double(v->eta_s));
	put_u32(im, job_addr(slot, MB_J_SCENE_ID), id32(v->scene_id));
}

/* An empty job slot: id 0, state empty, every other value unknown. */
static void job_clear(mb_image *im, int slot)
{
	mb_job_vals v;
	mb_job_vals_init(&v, 0);
	v.state = MB_JOB_EMPTY;
	job_write(im, slot, &v);
	put_u32(im, job_addr(slot, MB_J_JOB_ID), 0);
}

static void sens_write(mb_image *im, int slot, const sent *e)
{
	int have = !isnan(e->lux);
	put_u32(im, sens_addr(slot, MB_S_JOB_ID), id32(e->job));
	put_f32(im, sens_addr(slot, MB_S_LUX), e->lux);
	put_u32(im, sens_addr(slot, MB_S_ITERATION),
	        have ? mb_u32_of(e->iteration) : MB_U32_NA);
	put_u16(im, sens_addr(slot, MB_S_STATUS),
	        have ? MB_SENSOR_VALID : MB_SENSOR_WAITING);
	put_u16(im, sens_addr(slot, MB_S_LUX_SCALED),
	        mb_lux_scaled(e->lux, im->lux_scale));
	mb_put_str(&im->reg[sens_addr(slot, MB_S_NAME)], MB_NAME_BYTES / 2,
	           e->name);
}

static void sens_clear(mb_image *im, int slot)
{
	sent e = {0, "", -1, NAN, 0};
	sens_write(im, slot, &e);
	put_u32(im, sens_addr(slot, MB_S_JOB_ID), 0);
	put_u16(im, sens_addr(slot, MB_S_STATUS), MB_SENSOR_EMPTY);
}

/* The daemon block's counters, after any change to the tables. */
static void write_counts(mb_image *im)
{
	static const unsigned at[MB_JOB_NSTATES] = {
	        [MB_JOB_QUEUED] = MB_D_JOBS_QUEUED,
	        [MB_JOB_RUNNING] = MB_D_JOBS_RUNNING,
	        [MB_JOB_PAUSED] = MB_D_JOBS_PAUSED,
	        [MB_JOB_DONE] = MB_D_JOBS_DONE,
	        [MB_JOB_FAILED] = MB_D_JOBS_FAILED,
	        [MB_JOB_CANCELLED] = MB_D_JOBS_CANCELLED,
	};
	for (int st = MB_JOB_QUEUED; st < MB_JOB_NSTATES; st++)
		put_u16(im, MB_DAEMON_BASE + at[st],
		        mb_u16_of(im->by_state[st]));
	put_u16(im, MB_DAEMON_BASE + MB_D_JOBS_UNSLOTTED,
	        mb_u16_of(im->jobs_unslotted));
	put_u16(im, MB_DAEMON_BASE + MB_D_SENSORS_UNSLOTTED,
	        mb_u16_of(im->sensors_unslotted));
}

void mb_job_vals_init(mb_job_vals *v, uint64_t job_id)
{
	memset(v, 0, sizeof *v);
	v->job_id = job_id;
	v->state = MB_JOB_QUEUED;
	v->iteration = v->links = v->memory_bytes = -1;
	v->progress = v->residual = v->error_estimate = NAN;
	v->elapsed_s = v->eta_s = NAN;
}

/* ------------------------------------------------------------- creation */

mb_image *mb_image_new(const mb_config *c)
{
	mb_image *im = calloc(1, sizeof *im);
	if (!im)
		return NULL;
	if (pthread_mutex_init(&im->mu, NULL) != 0) {
		free(im);
		return NULL;
	}
	im->wo = c->word_order;
	im->job_slots = (unsigned)c->job_slots;
	im->sensor_slots = (unsigned)c->sensor_slots;
	im->lux_scale = c->lux_scale;
	im->start_mono_s = NAN;
	const unsigned d = MB_DAEMON_BASE;
	put_u16(im, d + MB_D_MAP_VERSION, MB_MAP_VERSION);
	put_u16(im, d + MB_D_JOB_SLOTS, (uint16_t)im->job_slots);
	put_u16(im, d + MB_D_SENSOR_SLOTS, (uint16_t)im->sensor_slots);
	put_u16(im, d + MB_D_WORD_ORDER, (uint16_t)im->wo);
	put_f32(im, d + MB_D_FLOAT_PROBE, 1.0);
	put_f32(im, d + MB_D_LUX_SCALE, im->lux_scale);
	put_u32(im, d + MB_D_UPTIME, MB_U32_NA);
	put_u32(im, d + MB_D_MEMORY, MB_U32_NA);
	write_counts(im);
	for (unsigned k = 0; k < im->job_slots; k++)
		job_clear(im, (int)k);
	for (unsigned k = 0; k < im->sensor_slots; k++)
		sens_clear(im, (int)k);
	return im;
}

void mb_image_free(mb_image *im)
{
	if (!im)
		return;
	pthread_mutex_destroy(&im->mu);
	free(im->jobs);
	free(im->sens);
	free(im);
}

/* ---------------------------------------------------------------- reads */

/* [addr, addr + n) inside one served block? */
static int served(const mb_image *im, unsigned addr, unsigned n)
{
	const struct {
		unsigned lo, len;
	} blocks[] = {
	        {MB_DAEMON_BASE, MB_DAEMON_REGS},
	        {MB_JOB_BASE, MB_JOB_STRIDE * im->job_slots},
	        {MB_SENSOR_BASE, MB_SENSOR_STRIDE * im->sensor_slots},
	};
	for (size_t i = 0; i < sizeof blocks / sizeof blocks[0]; i++)
		if (addr >= blocks[i].lo &&
		    addr + n <= blocks[i].lo + blocks[i].len)
			return 1;
	return 0;
}

int mb_image_read(mb_image *im, unsigned addr, unsigned n, uint16_t *out)
{
	if (n < 1 || n > 125)
		return 3; /* ILLEGAL DATA VALUE, as the spec orders checks */
	if (!served(im, addr, n))
		return 2; /* ILLEGAL DATA ADDRESS */
	const unsigned up = MB_DAEMON_BASE + MB_D_UPTIME;
	pthread_mutex_lock(&im->mu);
	if (addr < up + 2 && addr + n > up) {
		struct timespec ts;
		clock_gettime(CLOCK_MONOTONIC, &ts);
		double now = (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
		put_u32(im, up, mb_u32_of_double(now - im->start_mono_s));
	}
	memcpy(out, &im->reg[addr], n * sizeof *out);
	pthread_mutex_unlock(&im->mu);
	return 0;
}

void mb_image_set_clients(mb_image *im, unsigned clients)
{
	pthread_mutex_lock(&im->mu);
	put_u16(im, MB_DAEMON_BASE + MB_D_MODBUS_CLIENTS, mb_u16_of(clients));
	pthread_mutex_unlock(&im->mu);
}

void mb_image_daemon(mb_image *im, const mb_daemon_vals *v)
{
	pthread_mutex_lock(&im->mu);
	im->start_mono_s = v->start_mono_s;
	put_u32(im, MB_DAEMON_BASE + MB_D_MEMORY,
	        mb_kib_of_bytes(v->memory_bytes));
	pthread_mutex_unlock(&im->mu);
}

/* ----------------------------------------------------------------- jobs */

/* Index of the first job with id >= id. */
static size_t job_lb(const mb_image *im, uint64_t id)
{
	size_t lo = 0, hi = im->njobs;
	while (lo < hi) {
		size_t mid = lo + (hi - lo) / 2;
		if (im->jobs[mid].id < id)
			lo = mid + 1;
		else
			hi = mid;
	}
	return lo;
}

static int job_free_slot(mb_image *im)
{
	for (unsigned k = 0; k < im->job_slots; k++)
		if (!im->job_used[k])
			return (int)k;
	return -1;
}

/* Give free slots to unslotted jobs, lowest id first. */
static void job_promote(mb_image *im)
{
	for (size_t i = 0; i < im->njobs && im->jobs_unslotted; i++) {
		if (im->jobs[i].slot >= 0)
			continue;
		int k = job_free_slot(im);
		if (k < 0)
			return;
		im->job_used[k] = 1;
		im->jobs[i].slot = k;
		im->jobs_unslotted--;
		job_write(im, k, &im->jobs[i].v);
	}
}

/* A new entry at index i (the table has room); its slot if one is free. */
static jent *job_insert(mb_image *im, size_t i, uint64_t id)
{
	memmove(&im->jobs[i + 1], &im->jobs[i],
	        (im->njobs - i) * sizeof *im->jobs);
	im->njobs++;
	jent *e = &im->jobs[i];
	e->id = id;
	e->slot = job_free_slot(im);
	if (e->slot >= 0)
		im->job_used[e->slot] = 1;
	else
		im->jobs_unslotted++;
	return e;
}

static int grow(void **p, size_t *cap, size_t n, size_t size)
{
	if (n < *cap)
		return 0;
	size_t nc = *cap ? 2 * *cap : 16;
	void *q = realloc(*p, nc * size);
	if (!q)
		return -1;
	*p = q;
	*cap = nc;
	return 0;
}

int mb_image_job(mb_image *im, const mb_job_vals *v)
{
	if (v->job_id == 0 || v->state <= MB_JOB_EMPTY ||
	    v->state >= MB_JOB_NSTATES)
		return -2;
	pthread_mutex_lock(&im->mu);
	size_t i = job_lb(im, v->job_id);
	jent *e = i < im->njobs && im->jobs[i].id == v->job_id ? &im->jobs[i]
	                                                       : NULL;
	if (!e) {
		if (grow((void **)&im->jobs, &im->jcap, im->njobs,
		         sizeof *im->jobs) < 0) {
			pthread_mutex_unlock(&im->mu);
			return -2;
		}
		e = job_insert(im, i, v->job_id);
	} else {
		im->by_state[e->v.state]--;
	}
	e->v = *v;
	im->by_state[v->state]++;
	if (e->slot >= 0)
		job_write(im, e->slot, v);
	write_counts(im);
	int slot = e->slot;
	pthread_mutex_unlock(&im->mu);
	return slot;
}

/* ------------------------------------------------------------- sensors */

static int sens_cmp(const sent *e, uint64_t job, const char *name)
{
	if (e->job != job)
		return e->job < job ? -1 : 1;
	return strcmp(e->name, name);
}

/* Index of the first sensor >= (job, name). */
static size_t sens_lb(const mb_image *im, uint64_t job, const char *name)
{
	size_t lo = 0, hi = im->nsens;
	while (lo < hi) {
		size_t mid = lo + (hi - lo) / 2;
		if (sens_cmp(&im->sens[mid], job, name) < 0)
			lo = mid + 1;
		else
			hi = mid;
	}
	return lo;
}

static int sens_free_slot(mb_image *im)
{
	for (unsigned k = 0; k < im->sensor_slots; k++)
		if (!im->sens_used[k])
			return (int)k;
	return -1;
}

static void sens_promote(mb_image *im)
{
	for (size_t i = 0; i < im->nsens && im->sensors_unslotted; i++) {
		if (im->sens[i].slot >= 0)
			continue;
		int k = sens_free_slot(im);
		if (k < 0)
			return;
		im->sens_used[k] = 1;
		im->sens[i].slot = k;
		im->sensors_unslotted--;
		sens_write(im, k, &im->sens[i]);
	}
}

/* Drop sensor i: free and clear its slot (no promotion yet). */
static void sens_drop(mb_image *im, size_t i)
{
	sent *e = &im->sens[i];
	if (e->slot >= 0) {
		im->sens_used[e->slot] = 0;
		sens_clear(im, e->slot);
	} else {
		im->sensors_unslotted--;
	}
	memmove(e, e + 1, (im->nsens - i - 1) * sizeof *e);
	im->nsens--;
}

static int sens_name_ok(const char *name)
{
	return name && name[0] && strlen(name) < MB_SENSOR_NAME_MAX;
}

int mb_image_sensor(mb_image *im, uint64_t job_id, const char *name, double lux,
                    uint32_t iteration)
{
	if (job_id == 0 || !sens_name_ok(name))
		return -2;
	pthread_mutex_lock(&im->mu);
	size_t i = sens_lb(im, job_id, name);
	sent *e = i < im->nsens && sens_cmp(&im->sens[i], job_id, name) == 0
	                  ? &im->sens[i]
	                  : NULL;
	if (!e) {
		if (grow((void **)&im->sens, &im->scap, im->nsens,
		         sizeof *im->sens) < 0) {
			pthread_mutex_unlock(&im->mu);
			return -2;
		}
		memmove(&im->sens[i + 1], &im->sens[i],
		        (im->nsens - i) * sizeof *im->sens);
		im->nsens++;
		e = &im->sens[i];
		e->job = job_id;
		strcpy(e->name, name);
		e->slot = sens_free_slot(im);
		if (e->slot >= 0)
			im->sens_used[e->slot] = 1;
		else
			im->sensors_unslotted++;
	}
	e->lux = lux;
	e->iteration = iteration;
	if (e->slot >= 0)
		sens_write(im, e->slot, e);
	write_counts(im);
	int slot = e->slot;
	pthread_mutex_unlock(&im->mu);
	return slot;
}

void mb_image_sensor_remove(mb_image *im, uint64_t job_id, const char *name)
{
	if (!sens_name_ok(name))
		return;
	pthread_mutex_lock(&im->mu);
	size_t i = sens_lb(im, job_id, name);
	if (i < im->nsens && sens_cmp(&im->sens[i], job_id, name) == 0) {
		sens_drop(im, i);
		sens_promote(im);
		write_counts(im);
	}
	pthread_mutex_unlock(&im->mu);
}

void mb_image_job_remove(mb_image *im, uint64_t job_id)
{
	pthread_mutex_lock(&im->mu);
	size_t i = job_lb(im, job_id);
	if (i < im->njobs && im->jobs[i].id == job_id) {
		jent *e = &im->jobs[i];
		im->by_state[e->v.state]--;
		if (e->slot >= 0) {
			im->job_used[e->slot] = 0;
			job_clear(im, e->slot);
		} else {
			im->jobs_unslotted--;
		}
		memmove(e, e + 1, (im->njobs - i - 1) * sizeof *e);
		im->njobs--;
		job_promote(im);
	}
	size_t s = sens_lb(im, job_id, "");
	while (s < im->nsens && im->sens[s].job == job_id)
		sens_drop(im, s);
	sens_promote(im);
	write_counts(im);
	pthread_mutex_unlock(&im->mu);
}

int mb_image_job_slot(mb_image *im, uint64_t job_id)
{
	pthread_mutex_lock(&im->mu);
	size_t i = job_lb(im, job_id);
	int slot = i < im->njobs && im->jobs[i].id == job_id ? im->jobs[i].slot
	                                                     : -1;
	pthread_mutex_unlock(&im->mu);
	return slot;
}

int mb_image_sensor_slot(mb_image *im, uint64_t job_id, const char *name)
{
	if (!sens_name_ok(name))
		return -1;
	pthread_mutex_lock(&im->mu);
	size_t i = sens_lb(im, job_id, name);
	int slot = i < im->nsens && sens_cmp(&im->sens[i], job_id, name) == 0
	                   ? im->sens[i].slot
	                   : -1;
	pthread_mutex_unlock(&im->mu);
	return slot;
}
