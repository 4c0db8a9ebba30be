/*
 * sensors.c -- sensor nodes: the points where the daemon publishes
 * illuminance (Modbus), declared in the glTF document.
 *
 * A node declares a sensor by its name, "sensor:<name>", or by its
 * extras, {"luxrad_sensor": "<name>"}; both on one node must agree.  The
 * sensor sits at the node's world-space origin and faces the node's +Y
 * axis in world space (glTF's up), normalised.  Each bad declaration is
 * refused with a message naming the node: an empty, too long or
 * duplicate name, a control character, conflicting declarations, a
 * non-string extras value, a non-finite position, a zero or non-finite
 * normal.  Names are found again through a small open-addressing hash
 * set, so a document with many sensor nodes costs linear time.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

#define SENSOR_PREFIX "sensor:" /* a node name declaring one */

/* The sensor name node ni declares (len 0 = none), checked. */
static rad_status sensor_name(const sio_doc *d, int ni, sio_str *name,
                              rad_error *err)
{
	const sio_doc_node *n = &d->nodes[ni];
	const size_t plen = sizeof SENSOR_PREFIX - 1;
	int named = n->name.len >= plen &&
	            memcmp(n->name.s, SENSOR_PREFIX, plen) == 0;
	sio_val tag;
	sio_str extra = {"", 0};
	rad_status st = sio_doc_node_sensor(d, ni, &tag, &extra, err);
	if (st != RAD_OK)
		return st;
	int tagged = tag != SIO_VAL_ABSENT;
	sio_str by_name = {"", 0};
	if (named)
		by_name = (sio_str){n->name.s + plen, n->name.len - plen};
	if (tagged) {
		if (tag != SIO_VAL_STRING)
			return rad_fail(err, RAD_ERR_INVALID,
			                "node %d '%s': extras.%s must be a "
			                "string (the sensor's name)",
			                ni, n->name.s, SIO_SENSOR_EXTRA);
		*name = extra;
		if (named && (by_name.len != name->len ||
		              memcmp(by_name.s, name->s, name->len) != 0))
			return rad_fail(err, RAD_ERR_INVALID,
			                "node %d '%s': declares sensor '%s' by "
			                "its name and '%s' in extras.%s",
			                ni, n->name.s, by_name.s, name->s,
			                SIO_SENSOR_EXTRA);
	} else {
		*name = by_name;
	}
	if ((named || tagged) && name->len == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "node %d '%s': empty sensor name", ni,
		                n->name.s);
	if (name->len >= SIO_SENSOR_NAME_MAX)
		return rad_fail(err, RAD_ERR_INVALID,
		                "node %d: sensor name of %zu bytes (at most "
		                "%d)",
		                ni, name->len, SIO_SENSOR_NAME_MAX - 1);
	for (size_t k = 0; k < name->len; k++) {
		unsigned char ch = (unsigned char)name->s[k];
		if (ch < 0x20 || ch == 0x7F)
			return rad_fail(err, RAD_ERR_INVALID,
			                "node %d: sensor name has a control "
			                "character",
			                ni);
	}
	return RAD_OK;
}

/* Place the sensor at the node's origin, facing its +Y axis. */
static rad_status place(sio_sensor *g, int ni, const sio_mat4 *w,
                        rad_error *err)
{
	/* Scaled by the largest component first: a huge but finite axis
	 * must not overflow into an infinite length. */
	double big =
	        sio_max(fabs(w->m[4]), sio_max(fabs(w->m[5]), fabs(w->m[6])));
	double len = 0;
	for (int k = 0; k < 3; k++) {
		g->position[k] = w->m[12 + k];
		if (!isfinite(g->position[k]))
			return rad_fail(
			        err, RAD_ERR_INVALID,
			        "sensor '%s' (node %d): position is not "
			        "finite",
			        g->name, ni);
		g->normal[k] = big > 0 ? w->m[4 + k] / big : 0;
		len += g->normal[k] * g->normal[k];
	}
	if (!(big > 0) || !isfinite(big))
		return rad_fail(err, RAD_ERR_INVALID,
		                "sensor '%s' (node %d): normal (the node's +Y "
		                "axis in world space) is %s",
		                g->name, ni, big == 0 ? "zero" : "not finite");
	len = sqrt(len);
	for (int k = 0; k < 3; k++)
		g->normal[k] /= len;
	return RAD_OK;
}

/* FNV-1a: sensor names are short and few. */
static size_t hash(const char *s)
{
	uint64_t h = 14695981039346656037u;
	for (; *s; s++)
		h = (h ^ (unsigned char)*s) * 1099511628211u;
	return (size_t)h;
}

/* The slot holding name, or the free slot where it would go. */
static uint32_t *slot_of(const sio_sensor_set *ss, const char *name)
{
	size_t mask = ss->nslots - 1;
	for (size_t k = hash(name) & mask;; k = (k + 1) & mask) {
		uint32_t *slot = &ss->slots[k];
		if (!*slot || strcmp(ss->v[*slot - 1].name, name) == 0)
			return slot;
	}
}

/* Room for one more sensor, in v and in the hash set (kept half empty). */
static int grow(sio_sensor_set *ss)
{
	if (ss->n == ss->cap) {
		size_t cap = ss->cap ? 2 * ss->cap : 16;
		sio_sensor *v = realloc(ss->v, cap * sizeof(*v));
		if (!v)
			return 0;
		ss->v = v;
		ss->cap = cap;
	}
	if (2 * (ss->n + 1) <= ss->nslots)
		return 1;
	size_t nslots = ss->nslots ? 2 * ss->nslots : 32;
	uint32_t *slots = calloc(nslots, sizeof(*slots));
	if (!slots)
		return 0;
	free(ss->slots);
	ss->slots = slots;
	ss->nslots = nslots;
	for (size_t i = 0; i < ss->n; i++)
		*slot_of(ss, ss->v[i].name) = (uint32_t)(i + 1);
	return 1;
}

rad_status sio_sensor_node(sio_sensor_set *ss, int ni, const sio_mat4 *w,
                           rad_error *err)
{
	sio_str name = {"", 0};
	rad_status st = sensor_name(ss->d, ni, &name, err);
	if (st != RAD_OK || name.len == 0)
		return st;
	sio_sensor g;
	memset(&g, 0, sizeof g);
	memcpy(g.name, name.s, name.len + 1);
	g.node = (uint32_t)ni;
	st = place(&g, ni, w, err);
	if (st != RAD_OK)
		return st;
	if (!grow(ss))
		return rad_fail(err, RAD_ERR_NOMEM,
		                "out of memory for %zu sensors", ss->n + 1);
	uint32_t *slot = slot_of(ss, g.name);
	if (*slot)
		return rad_fail(err, RAD_ERR_INVALID,
		                "sensor '%s' declared twice (nodes %d and %d)",
		                g.name, (int)ss->v[*slot - 1].node, ni);
	ss->v[ss->n++] = g;
	*slot = (uint32_t)ss->n;
	return RAD_OK;
}

void sio_sensor_set_take(sio_sensor_set *ss, sio_sensor **out, size_t *n)
{
	*out = ss->n ? ss->v : NULL;
	*n = ss->n;
	if (!ss->n)
		free(ss->v);
	ss->v = NULL;
	ss->n = ss->cap = 0;
}

void sio_sensor_set_free(sio_sensor_set *ss)
{
	free(ss->v);
	free(ss->slots);
}
