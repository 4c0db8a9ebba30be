/*
 * scenes.c -- the scene registry and the scene.* commands.
 *
 * A scene arrives as bytes (never a path), is parsed once by
 * sio_load on the store thread (never on the I/O thread: a large
 * upload takes seconds), stored (store.h: the bytes as uploaded, so a
 * restart parses them again) and then shared read-only by every job on
 * it.  The upload task takes the connection's input buffer with the
 * payload in it instead of copying it.
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

#include "log.h"
#include "server.h"

void srv_scene_ref(srv_scene *sc)
{
	atomic_fetch_add(&sc->refs, 1);
}

void srv_scene_unref(srv_scene *sc)
{
	if (!sc || atomic_fetch_sub(&sc->refs, 1) != 1)
		return;
	rad_scene_free(sc->scene);
	sio_sensors_free(sc->sensors);
	free(sc);
}

srv_scene *srv_scene_find(srv *s, uint64_t id)
{
	for (srv_scene *sc = s->scenes; sc; sc = sc->next)
		if (sc->id == id)
			return sc;
	return NULL;
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
		json_array_append_new(a, srv_jreal(v[i]));
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
	COUNT_(materials)
	COUNT_(materials_offered)
	COUNT_(lights)
	COUNT_(emitters)
	COUNT_(nodes)
#undef COUNT_
	json_object_set_new(bounds, "min", vec3(sc->lo));
	json_object_set_new(bounds, "max", vec3(sc->hi));
	warnings_text(sc, warn, sizeof(warn));
	json_object_set_new(o, "scene", json_integer((json_int_t)sc->id));
	json_object_set_new(o, "name", json_string(sc->name));
	/* Not "bytes": at the top of a header that announces a payload. */
	json_object_set_new(o, "size_bytes",
	                    json_integer((json_int_t)sc->bytes));
	json_object_set_new(o, "counts", counts);
	json_object_set_new(o, "bounds", bounds);
	json_object_set_new(o, "memory_bytes", json_integer(sc->mem.total));
	json_object_set_new(o, "warnings", json_string(warn));
	return o;
}

/* ----------------------------------------------------------------- upload */

typedef struct upload_task {
	srv_task t;
	unsigned char *buf;           /* the connection's input buffer */
	const unsigned char *payload; /* inside buf */
	size_t len;
	char name[256];
	srv_scene *sc; /* result */
	rp_err code;   /* error */
	char msg[600];
} upload_task;

static void upload_run(srv *s, srv_task *t)
{
	upload_task *u = (upload_task *)t;
	rad_error err = {0};
	double t0 = rad_seconds();
	uint64_t id = 0;
	char msg[512] = "";

	u->sc = srv_scene_load(0, u->name, srv_now_unix(), u->payload, u->len,
	                       &err);
	if (!u->sc) {
		u->code = srv_err_from_rad(err.code);
		snprintf(u->msg, sizeof(u->msg), "scene refused: %s", err.msg);
	} else {
		pthread_mutex_lock(&s->store_mu);
		int rc = srv_store_scene_add(s->store, u->name, u->payload,
		                             u->len, &id, msg, sizeof(msg));
		pthread_mutex_unlock(&s->store_mu);
		if (rc != 0) {
			u->code = RP_ERR_IO;
			snprintf(u->msg, sizeof(u->msg),
			         "cannot store the scene: %s", msg);
			srv_scene_unref(u->sc);
			u->sc = NULL;
		} else {
			u->sc->id = id;
			srv_info("scene %llu '%s': %zu bytes, %u polygons, "
			         "loaded in %.3f s",
			         (unsigned long long)id, u->name, u->len,
			         u->sc->counts.polygons, rad_seconds() - t0);
		}
	}
	free(u->buf);
	u->buf = NULL;
}

static void upload_done(srv *s, srv_task *t)
{
	upload_task *u = (upload_task *)t;
	json_t *reply;

	s->scenes_pending--;
	if (u->sc) {
		srv_scene_register(s, u->sc);
		reply = rp_reply_ok(t->id);
		json_t *body = srv_scene_json(u->sc);
		json_object_update(reply, body);
		json_decref(body);
	} else {
		reply = rp_reply_error(t->id, u->code, "%s", u->msg);
	}
	srv_reply_deferred(s, t->conn_id, reply);
	json_decref(t->id);
	free(u);
}

cmd_result srv_cmd_scene_upload(srv_req *r)
{
	srv *s = r->s;
	const char *name = NULL;

	if (rp_arg_string(r->hdr, "name", 0, &name, &r->err) < 0)
		return CMD_ERROR;
	if (name && strlen(name) > 255)
		return srv_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "\"name\" is longer than 255 bytes");
	if (!r->payload)
		return srv_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "scene.upload needs the scene as a payload "
		                    "(\"bytes\": N, then N bytes)");
	if (s->nscenes + s->scenes_pending >= s->cfg.max_scenes)
		return srv_req_fail(r, RP_ERR_LIMIT,
		                    "max_scenes (%d) scenes exist: delete one "
		                    "first",
		                    s->cfg.max_scenes);
	upload_task *u = calloc(1, sizeof(*u));
	if (!u)
		return srv_req_fail(r, RP_ERR_NOMEM, "out of memory");
	size_t off = (size_t)(r->payload - (r->c->in + r->c->in_off));
	size_t in_off = r->c->in_off;
	u->buf = srv_conn_steal_input(r->c, r->frame_used);
	if (!u->buf) {
		free(u);
		return srv_req_fail(r, RP_ERR_NOMEM, "out of memory");
	}
	u->payload = u->buf + in_off + off;
	u->len = r->payload_len;
	snprintf(u->name, sizeof(u->name), "%s", name ? name : "");
	u->t.run = upload_run;
	u->t.done = upload_done;
	u->t.conn_id = r->c->id;
	u->t.id = json_incref(r->id);
	s->scenes_pending++;
	srv_pool_submit(&s->store_pool, &u->t);
	return CMD_DEFERRED;
}

/* ------------------------------------------------------------ list / info */

cmd_result srv_cmd_scene_list(srv_req *r)
{
	json_t *arr = json_array();
	for (srv_scene *sc = r->s->scenes; sc; sc = sc->next) {
		json_t *o = json_object();
		json_object_set_new(o, "id", json_integer((json_int_t)sc->id));
		json_object_set_new(o, "name", json_string(sc->name));
		json_object_set_new(o, "bytes",
		                    json_integer((json_int_t)sc->bytes));
		json_object_set_new(o, "polygons",
		                    json_integer(sc->counts.polygons));
		json_object_set_new(o, "jobs", json_integer(sc->njobs));
		json_object_set_new(o, "memory_bytes",
		                    json_integer(sc->mem.total));
		json_object_set_new(o, "created", json_real(sc->created));
		json_array_append_new(arr, o);
	}
	json_object_set_new(r->res, "scenes", arr);
	return CMD_REPLY;
}

static srv_scene *req_scene(srv_req *r)
{
	uint64_t id = 0;
	if (rp_arg_u64(r->hdr, "scene", 1, &id, &r->err) != 0)
		return NULL;
	srv_scene *sc = srv_scene_find(r->s, id);
	if (!sc)
		srv_req_fail(r, RP_ERR_NOT_FOUND, "no scene %llu",
		             (unsigned long long)id);
	return sc;
}

cmd_result srv_cmd_scene_info(srv_req *r)
{
	srv_scene *sc = req_scene(r);
	if (!sc)
		return CMD_ERROR;
	json_t *body = srv_scene_json(sc), *jobs = json_array();
	for (srv_job *j = r->s->jobs; j; j = j->next)
		if (j->scene == sc)
			json_array_append_new(jobs,
			                      json_integer((json_int_t)j->id));
	json_object_update(r->res, body);
	json_decref(body);
	json_object_set_new(r->res, "jobs", jobs);
	return CMD_REPLY;
}

/* ----------------------------------------------------------------- delete */

typedef struct scene_del_task {
	srv_task t;
	uint64_t scene;
	int failed;
	char msg[512];
} scene_del_task;

static void scene_del_run(srv *s, srv_task *t)
{
	scene_del_task *d = (scene_del_task *)t;
	pthread_mutex_lock(&s->store_mu);
	d->failed = srv_store_scene_delete(s->store, d->scene, d->msg,
	                                   sizeof(d->msg)) != 0;
	pthread_mutex_unlock(&s->store_mu);
}

static void scene_del_done(srv *s, srv_task *t)
{
	scene_del_task *d = (scene_del_task *)t;
	json_t *reply;
	if (d->failed) {
		srv_error("scene %llu: store delete failed: %s",
		          (unsigned long long)d->scene, d->msg);
		reply = rp_reply_error(
		        t->id, RP_ERR_IO,
		        "scene %llu was freed but its file could "
		        "not be removed: %s",
		        (unsigned long long)d->scene, d->msg);
	} else {
		reply = rp_reply_ok(t->id);
	}
	srv_reply_deferred(s, t->conn_id, reply);
	json_decref(t->id);
	free(d);
}

cmd_result srv_cmd_scene_delete(srv_req *r)
{
	srv *s = r->s;
	srv_scene *sc = req_scene(r);
	if (!sc)
		return CMD_ERROR;
	if (sc->njobs > 0)
		return srv_req_fail(r, RP_ERR_BUSY,
		                    "scene %llu is used by %d job%s: delete "
		                    "them first",
		                    (unsigned long long)sc->id, sc->njobs,
		                    sc->njobs == 1 ? "" : "s");
	scene_del_task *d = calloc(1, sizeof(*d));
	if (!d)
		return srv_req_fail(r, RP_ERR_NOMEM, "out of memory");
	for (srv_scene **pp = &s->scenes; *pp; pp = &(*pp)->next) {
		if (*pp == sc) {
			*pp = sc->next;
			break;
		}
	}
	s->nscenes--;
	srv_info("scene %llu '%s' deleted", (unsigned long long)sc->id,
	         sc->name);
	d->scene = sc->id;
	srv_scene_unref(sc);
	d->t.run = scene_del_run;
	d->t.done = scene_del_done;
	d->t.conn_id = r->c->id;
	d->t.id = json_incref(r->id);
	srv_pool_submit(&s->store_pool, &d->t);
	return CMD_DEFERRED;
}
