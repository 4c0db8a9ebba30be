/*
 * engine_json.h -- the engine's options and statistics as JSON, written
 * once for every program that shows them: luxrad-solve --json, the
 * daemon's job.info, iteration events and stored jobs.
 *
 * Both encodings walk rad.h's tables (RAD_OPTIONS, RAD_STATS), so a new
 * option or statistic appears everywhere with its name from the table and
 * nowhere else needs an edit.  Functions here allocate jansson values
 * and return NULL only when jansson cannot allocate.
 */
#ifndef LUXRAD_ENGINE_JSON_H
#define LUXRAD_ENGINE_JSON_H

#include <jansson.h>
#include <stddef.h>

#include "rad.h"

/* A number, or null for NaN and infinities (JSON has neither). */
json_t *ej_real(double v);

/*
 * <stats>: the RAD_STATS fields under their keys, those with a group
 * inside that object ("links": {"stored", "ss", ...}), energy_hist as an
 * array and memory as {"total_bytes", "peak_bytes", "peak_work_bytes",
 * "peak_own_bytes", "by_kind": {kind: bytes}}.
 */
json_t *ej_stats(const rad_stats *st);
json_t *ej_memory(const rad_mem_report *m);

/* Every option of RAD_OPTIONS under its key: numbers, booleans, and
 * choice names for ENUMs. */
json_t *ej_options(const rad_options *o);

typedef enum ej_status {
	EJ_OK = 0,
	EJ_TYPE,    /* a value of the wrong JSON type, or not an object */
	EJ_INVALID, /* an unknown key, or a value out of range */
} ej_status;

/*
 * Set the options an object names, over what *o holds.  "accuracy" is
 * applied first (rad_options_accuracy), so that any option it sets that
 * the object also names wins whatever the order of the keys.  NULL sets
 * nothing.  On failure msg holds a sentence naming the key and *o may be
 * partly set.
 */
ej_status ej_options_set(rad_options *o, json_t *obj, char *msg, size_t len);

#endif
