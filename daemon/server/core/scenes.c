/*
 * scenes.c -- the scene registry: loading, storing and forgetting scenes.
 *
 * A scene arrives as bytes (never a path), is parsed once by
 * sio_load on the store thread (never on the I/O thread: a large
 * upload takes seconds), stored (store.h: the bytes as uploaded, so a
 * restart parses them again) and then shared read-only by every job on
 * it.
 *
 * The registry (a list owned by the I/O thread) holds one reference;
 * each job and each published solution holds another.  scene.delete
 * refuses while a job uses the scene (njobs counts jobs being created
 * too), removes it from the registry at once (status stops counting it)
 * and the engine scene is freed when the last reference goes.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"
#include "engine_json.h"
#include "log.h"

void srv_scene_unref(srv_scene *sc)
{
	if (!sc || atomic_fetch_sub(&sc->refs, 1) != 1)
		return;
	rad_scene_free(sc->scene);
	sio_sensors_free(sc->sensors);
	free(sc);
}

srv_scene *srv_scene_load(uint64_t id, const char *name, double created,
                          const void *bytes, size_t len, rad_error *err)
{
	srv_scene *sc = calloc(1, sizeof(*sc));
	if (!sc) {
		err->code = RAD_ERR_NOMEM;
		snprintf(err->msg, sizeof(err->msg), "scene: out of memory");
		return NULL;
	}
	/* Sensor nodes (Modbus) come with the scene, from the same bytes at
	 * every load, so a restart finds them again; a bad declaration
	 * refuses the scene. */
	if (sio_load(bytes, len, &sc->scene, &sc->info, &sc->sensors,
	             &sc->nsensors, err) != RAD_OK) {
		free(sc);
		return NULL;
	}
	atomic_init(&sc->refs, 1);
	sc->id = id;
	snprintf(sc->name, sizeof(sc->name), "%s", name ? name : "");
	sc->bytes = len;
	sc->created = created;
	rad_scene_counts_get(sc->scene, &sc->counts);
	rad_scene_bounds(sc->scene, sc->lo, sc->hi);
	rad_scene_memory(sc->scene, &sc->mem);
	return sc;
}

void srv_scene_register(srv *s, srv_scene *sc)
{
	if (!sc->name[0])
		snprintf(sc->name, sizeof(sc->name), "scene-%llu",
		         (unsigned long long)sc->id);
	/* Keep id order for listings: append. */
	srv_scene **pp = &s->scenes;
	while (*pp)
		pp = &(*pp)->next;
	sc->next = NULL;
	*pp = sc;
	s->nscenes++;
}

static json_t *vec3(const double v[3])
{
	json_t *a = json_array();
	for (int i = 0; i < 3; i++)
		json_array_append_new(a, ej_real(v[i]));
	return a;
}

/* Append "; " + a formatted note to out (n bytes used so far). */
static void note(char *out, size_t len, size_t *n, const char *fmt, ...)
        __attribute__((format(printf, 4, 5)));
static void note(char *out, size_t len, size_t *n, const char *fmt, ...)
{
	va_list ap;
	if (*n + 3 >= len)
		return;
	if (*n) {
		memcpy(out + *n, "; ", 3);
		*n += 2;
	}
	va_start(ap, fmt);
	int k = vsnprintf(out + *n, len - *n, fmt, ap);
	va_end(ap);
	if (k > 0)
		*n = *n + (size_t)k < len ? *n + (size_t)k : len - 1;
}

/* The importer's notes in one line. */
static void warnings_text(const srv_scene *sc, char *out, size_t len)
{
	const sio_info *g = &sc->info;
	size_t n = 0;
	out[0] = '\0';
	if (g->primitives_skipped)
		note(out, len, &n, "%u primitives skipped (not triangles)",
		     g->primitives_skipped);
	if (g->textures_ignored)
		note(out, len, &n, "%u textures ignored", g->textures_ignored);
	if (g->metallic_materials)
		note(out, len, &n, "%u metallic materials taken as diffuse",
		     g->metallic_materials);
	if (g->warnings[0])
		note(out, len, &n, "%s", g->warnings);
}

json_t *srv_scene_json(const srv_scene *sc)
{
	const rad_scene_counts *c = &sc->counts;
	char warn[1024];
	json_t *o = json_object(), *counts = json_object();
	json_t *bounds = json_object();

#define COUNT_(f) json_object_set_new(counts, #f, json_integer(c->f));
	COUNT_(triangles_in)
	COUNT_(triangles_nonfinite)
	COUNT_(triangles_degenerate)
	COUNT_(triangles_duplicate)
	COUNT_(polygons)
	COUNT_(polygons_cut)
	COUNT_(quads)
	COUNT_(back_faces)
	COUNT_(materials)
	COUNT_(materials_offered)
	COUNT_(lights)
	COUNT_(emitters)
	COUNT_(nodes)
#undef COUNT_
	json_t *tex = json_object();
	json_object_set_new(tex, "read", json_integer(sc->info.textures_read));
	json_object_set_new(tex, "images_decoded",
	                    json_integer(sc->info.images_decoded));
	json_object_set_new(tex, "textured_triangles",
	                    json_integer(sc->info.textured_triangles));
	json_object_set_new(tex, "ignored",
	                    json_integer(sc->info.textures_ignored));
	json_object_set_new(bounds, "min", vec3(sc->lo));
	json_object_set_new(bounds, "max", vec3(sc->hi));
	warnings_text(sc, warn, sizeof(warn));
	json_object_set_new(o, "scene", json_integer((json_int_t)sc->id));
	json_object_set_new(o, "name", json_string(sc->name));
	json_object_set_new(o, "owner", json_string(sc->owner));
	/* Not "bytes": at the top of a header that announces a payload. */
	json_object_set_new(o, "size_bytes",
	                    json_integer((json_int_t)sc->bytes));
	json_object_set_new(o, "counts", counts);
	json_object_set_new(o, "bounds", bounds);
	json_object_set_new(o, "textures", tex);
	json_object_set_new(o, "memory_bytes", json_integer(sc->mem.total));
	json_object_set_new(o, "warnings", json_string(warn));
	return o;
}

/* ------------------------------------------------ add / remove (store) */

int srv_scene_create(srv *s, const char *name, const char *owner,
                     const void *bytes, size_t len, srv_scene **out,
                     rad_error *err)
{
	double t0 = rad_seconds();
	uint64_t id = 0;
	char msg[512] = "";

	*out = NULL;
	srv_scene *sc =
	        srv_scene_load(0, name, srv_now_unix(), bytes, len, err);
	if (!sc)
		return -1;
	pthread_mutex_lock(&s->store_mu);
	snprintf(sc->owner, sizeof(sc->owner), "%s", owner);
	int rc = srv_store_scene_add(s->store, name, owner, bytes, len, &id,
	                             msg, sizeof(msg));
	pthread_mutex_unlock(&s->store_mu);
	if (rc != 0) {
		snprintf(err->msg, sizeof(err->msg), "%s", msg);
		srv_scene_unref(sc);
		return -2;
	}
	sc->id = id;
	srv_info("scene %llu '%s': %zu bytes, %u polygons, loaded in %.3f s",
	         (unsigned long long)id, name, len, sc->counts.polygons,
	         rad_seconds() - t0);
	*out = sc;
	return 0;
}

void srv_scene_unregister(srv *s, srv_scene *sc)
{
	for (srv_scene **pp = &s->scenes; *pp; pp = &(*pp)->next) {
		if (*pp == sc) {
			*pp = sc->next;
			s->nscenes--;
			srv_info("scene %llu '%s' deleted",
			         (unsigned long long)sc->id, sc->name);
			return;
		}
	}
}

int srv_scene_forget(srv *s, uint64_t id, char *msg, size_t msglen)
{
	pthread_mutex_lock(&s->store_mu);
	int rc = srv_store_scene_delete(s->store, id, msg, msglen);
	pthread_mutex_unlock(&s->store_mu);
	if (rc != 0)
		srv_error("scene %llu: store delete failed: %s",
		          (unsigned long long)id, msg);
	return rc;
}
