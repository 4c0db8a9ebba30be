/*
 * pack.c -- see pack.h.
 *
 * DESIGN
 * The document is parsed with jansson, rewritten and written back; no
 * number is touched (jansson prints doubles with 17 digits, which read
 * back to the same double), so a packed scene loads to the same scene.
 * Buffers are laid end to end in the binary chunk, each at a multiple of
 * 8 bytes, and every bufferView's byteOffset moves by its buffer's
 * place; images read from a uri are appended after them with a
 * bufferView each and their mimeType (glTF allows PNG and JPEG there:
 * from the data: URI's media type or the file's extension), and named by
 * their uri when they had no name, so that the loader's messages name
 * the file.  A Git LFS pointer where a buffer should be is refused by
 * that name (a clone without git-lfs has those in place of .bin files).
 *
 * A path is refused before anything is opened when it has a scheme,
 * starts with '/', or has a ".." segment once percent-decoded; what is
 * opened must then resolve (realpath) inside the folder's own real path,
 * so a symbolic link out of it is refused too, and be a regular file.
 */
#include <ctype.h>
#include <errno.h>
#include <jansson.h>
#include <limits.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "pack_int.h"

#define IMAGE_MAX (1ull << 30) /* one image file, at most */

/* 1 if the file at path is a Git LFS pointer. */
static int lfs_pointer_file(const char *path)
{
	unsigned char head[64];
	FILE *f = fopen(path, "rb");
	if (!f)
		return 0;
	size_t n = fread(head, 1, sizeof(head), f);
	fclose(f);
	return sio_is_lfs_pointer(head, n);
}

/* ------------------------------------------------------------------ URIs */

static int hexval(int c)
{
	return isdigit(c) ? c - '0' : isxdigit(c) ? tolower(c) - 'a' + 10 : -1;
}

/* Percent-decode uri into out[outlen]; -1 when malformed or too long. */
static int uri_decode(const char *uri, char *out, size_t outlen)
{
	size_t n = 0;
	for (const char *p = uri; *p; p++) {
		int c = (unsigned char)*p;
		if (c == '%') {
			int h = hexval((unsigned char)p[1]);
			int l = h < 0 ? -1 : hexval((unsigned char)p[2]);
			if (l < 0)
				return -1;
			c = 16 * h + l;
			p += 2;
		}
		if (c == 0 || n + 1 >= outlen)
			return -1;
		out[n++] = (char)c;
	}
	out[n] = '\0';
	return 0;
}

/* "scheme:" before any '/' (RFC 3986). */
static int has_scheme(const char *uri)
{
	if (!isalpha((unsigned char)uri[0]))
		return 0;
	for (const char *p = uri + 1; *p && *p != '/'; p++) {
		if (*p == ':')
			return 1;
		if (!isalnum((unsigned char)*p) && !strchr("+.-", *p))
			return 0;
	}
	return 0;
}

static int has_dotdot(const char *path)
{
	for (const char *p = path; *p;) {
		size_t n = strcspn(p, "/");
		if (n == 2 && p[0] == '.' && p[1] == '.')
			return 1;
		p += n + (p[n] == '/');
	}
	return 0;
}

/* What a uri belongs to: a buffer, an image, a node (its photometric
 * file, extras.luxrad_photometry). */
enum { KIND_BUFFER, KIND_IMAGE, KIND_NODE };

static const char *kind_name(int kind)
{
	return kind == KIND_IMAGE  ? "image"
	       : kind == KIND_NODE ? "node"
	                           : "buffer";
}

/* Read the file a relative uri names, inside the scene's folder: exactly
 * need bytes (need > 0), or all of it up to IMAGE_MAX (need == 0). */
static rad_status read_relative(packer *pk, int kind, size_t idx,
                                const char *uri, size_t need,
                                unsigned char **out, size_t *len)
{
	char rel[PATH_MAX], full[2 * PATH_MAX + 2], real[PATH_MAX];
	const char *what = kind_name(kind);
	if (uri_decode(uri, rel, sizeof(rel)) != 0)
		return rad_fail(pk->err, RAD_ERR_INVALID,
		                "%s %zu: uri '%.80s' is not a valid path", what,
		                idx, uri);
	if (rel[0] == '/' || has_dotdot(rel))
		return rad_fail(pk->err, RAD_ERR_INVALID,
		                "%s %zu: uri '%.80s' leaves the scene's folder "
		                "(only paths inside it are read)",
		                what, idx, uri);
	snprintf(full, sizeof(full), "%s/%s", pk->dir, rel);
	if (!realpath(full, real))
		return rad_fail(pk->err, RAD_ERR_IO,
		                "%s %zu: '%.80s' not found beside the scene "
		                "(%s): %s",
		                what, idx, rel, pk->dir, strerror(errno));
	size_t dl = strlen(pk->realdir);
	if (strncmp(real, pk->realdir, dl) != 0 || real[dl] != '/')
		return rad_fail(pk->err, RAD_ERR_INVALID,
		                "%s %zu: '%.80s' resolves outside the scene's "
		                "folder",
		                what, idx, rel);
	struct stat sb;
	if (stat(real, &sb) != 0 || !S_ISREG(sb.st_mode))
		return rad_fail(pk->err, RAD_ERR_INVALID,
		                "%s %zu: '%.80s' is not a regular file", what,
		                idx, rel);
	if (need && lfs_pointer_file(real))
		return rad_fail(pk->err, RAD_ERR_INVALID,
		                "buffer %zu: '%.80s' is " SIO_LFS_HINT, idx,
		                rel);
	if (need && (uint64_t)sb.st_size < need)
		return rad_fail(
		        pk->err, RAD_ERR_INVALID,
		        "buffer %zu: '%.80s' has %lld bytes, byteLength "
		        "says %zu",
		        idx, rel, (long long)sb.st_size, need);
	if (!need && (uint64_t)sb.st_size > IMAGE_MAX)
		return rad_fail(pk->err, RAD_ERR_LIMIT,
		                "%s %zu: '%.80s' is larger than 1 GiB", what,
		                idx, rel);
	FILE *f = fopen(real, "rb");
	if (!f)
		return rad_fail(pk->err, RAD_ERR_IO,
		                "%s %zu: cannot open "
		                "'%.80s': %s",
		                what, idx, rel, strerror(errno));
	rad_status st = sio_pack_read_stream(f, rel, need ? need : IMAGE_MAX,
	                                     out, len, pk->err);
	fclose(f);
	if (!st && need && *len != need) {
		free(*out);
		return rad_fail(pk->err, RAD_ERR_IO,
		                "buffer %zu: '%.80s' ended after %zu bytes",
		                idx, rel, *len);
	}
	return st;
}

static int b64val(int c)
{
	if (c >= 'A' && c <= 'Z')
		return c - 'A';
	if (c >= 'a' && c <= 'z')
		return c - 'a' + 26;
	if (c >= '0' && c <= '9')
		return c - '0' + 52;
	return c == '+' ? 62 : c == '/' ? 63 : -1;
}

/* Decode a base64 data: URI; *mime gets its media type (may be ""). */
static rad_status read_data_uri(packer *pk, int kind, size_t idx,
                                const char *uri, char *mime, size_t mimelen,
                                unsigned char **out, size_t *len)
{
	const char *comma = strchr(uri, ',');
	const char *what = kind_name(kind);
	size_t head = comma ? (size_t)(comma - uri) : 0;
	if (!comma || head < 12 || strncmp(comma - 7, ";base64", 7) != 0)
		return rad_fail(pk->err, RAD_ERR_INVALID,
		                "%s %zu: data: URI is not base64", what, idx);
	size_t ml = head - 5 - 7; /* between "data:" and ";base64" */
	snprintf(mime, mimelen, "%.*s", (int)ml, uri + 5);
	const char *p = comma + 1;
	size_t n = strlen(p);
	unsigned char *buf = malloc(n / 4 * 3 + 3);
	if (!buf)
		return rad_fail(pk->err, RAD_ERR_NOMEM, "out of memory");
	size_t o = 0;
	unsigned acc = 0;
	int bits = 0;
	for (size_t i = 0; i < n; i++) {
		if (p[i] == '=')
			break;
		int v = b64val((unsigned char)p[i]);
		if (v < 0) {
			free(buf);
			return rad_fail(pk->err, RAD_ERR_INVALID,
			                "%s %zu: data: URI has a character "
			                "outside base64",
			                what, idx);
		}
		acc = (acc << 6) | (unsigned)v;
		bits += 6;
		if (bits >= 8) {
			bits -= 8;
			buf[o++] = (unsigned char)(acc >> bits);
		}
	}
	*out = buf;
	*len = o;
	pk->info.data_uris++;
	return RAD_OK;
}

/* The bytes a uri names: a data: URI, or a file beside the scene (need
 * bytes of it; all of it for an image, need 0).  *mime: the data: URI's
 * media type, else "". */
static rad_status read_uri(packer *pk, int kind, size_t idx, const char *uri,
                           size_t need, char *mime, size_t mimelen,
                           unsigned char **out, size_t *len)
{
	mime[0] = '\0';
	if (strncmp(uri, "data:", 5) == 0)
		return read_data_uri(pk, kind, idx, uri, mime, mimelen, out,
		                     len);
	if (has_scheme(uri))
		return rad_fail(pk->err, RAD_ERR_INVALID,
		                "%s %zu: uri '%.80s' is not read: only data: "
		                "URIs and files beside the scene",
		                kind_name(kind), idx, uri);
	rad_status st = read_relative(pk, kind, idx, uri, need, out, len);
	if (!st && kind == KIND_IMAGE)
		pk->info.images_read++;
	else if (!st && kind == KIND_NODE)
		pk->info.photometry_read++;
	else if (!st)
		pk->info.buffers_read++;
	return st;
}

/* ------------------------------------------------------- the binary chunk */

static json_int_t int_member(json_t *o, const char *key, json_int_t def)
{
	json_t *v = json_object_get(o, key);
	return json_is_integer(v) ? json_integer_value(v) : def;
}

/* Buffers end to end; *base[i] the offset of buffer i. */
static rad_status pack_buffers(packer *pk, json_t *buffers, size_t **base)
{
	size_t nb = json_array_size(buffers);
	*base = calloc(nb ? nb : 1, sizeof(**base));
	if (!*base)
		return rad_fail(pk->err, RAD_ERR_NOMEM, "out of memory");
	for (size_t i = 0; i < nb; i++) {
		json_t *b = json_array_get(buffers, i);
		json_int_t bl = int_member(b, "byteLength", -1);
		const char *uri = json_string_value(json_object_get(b, "uri"));
		if (bl < 0)
			return rad_fail(pk->err, RAD_ERR_INVALID,
			                "buffer %zu has no byteLength", i);
		if (!uri && i == 0 && pk->glb_bin) { /* the GLB's own chunk */
			if ((size_t)bl > pk->nglb_bin)
				return rad_fail(
				        pk->err, RAD_ERR_INVALID,
				        "buffer 0: byteLength %lld, the "
				        "GLB's binary chunk %zu bytes",
				        (long long)bl, pk->nglb_bin);
			rad_status st = sio_pack_bin_append(
			        pk, pk->glb_bin, (size_t)bl, &(*base)[0]);
			if (st)
				return st;
			continue;
		}
		if (!uri)
			return rad_fail(pk->err, RAD_ERR_INVALID,
			                "buffer %zu has no uri (only a GLB's "
			                "first buffer may omit it)",
			                i);
		unsigned char *bytes = NULL;
		size_t len = 0;
		char mime[64];
		rad_status st = RAD_OK;
		if (bl > 0 || strncmp(uri, "data:", 5) == 0)
			st = read_uri(pk, KIND_BUFFER, i, uri, (size_t)bl, mime,
			              sizeof(mime), &bytes, &len);
		if (!st && len < (size_t)bl) {
			free(bytes);
			bytes = NULL;
			st = rad_fail(
			        pk->err, RAD_ERR_INVALID,
			        "buffer %zu: the data: URI decodes to %zu "
			        "bytes, byteLength says %lld",
			        i, len, (long long)bl);
		}
		if (!st)
			st = sio_pack_bin_append(pk, bytes, (size_t)bl,
			                         &(*base)[i]);
		free(bytes);
		if (st)
			return st;
	}
	return RAD_OK;
}

/* Every bufferView into the one buffer, at its buffer's place. */
static rad_status move_views(packer *pk, json_t *views, const size_t *base,
                             size_t nbuffers)
{
	for (size_t i = 0; i < json_array_size(views); i++) {
		json_t *v = json_array_get(views, i);
		json_int_t b = int_member(v, "buffer", -1);
		if (b < 0 || (size_t)b >= nbuffers)
			return rad_fail(pk->err, RAD_ERR_INVALID,
			                "bufferView %zu names no buffer", i);
		json_int_t off = int_member(v, "byteOffset", 0);
		json_object_set_new(v, "buffer", json_integer(0));
		json_object_set_new(v, "byteOffset",
		                    json_integer(off + (json_int_t)base[b]));
	}
	return RAD_OK;
}

static const char *mime_of(const char *uri, const char *mime)
{
	if (!strcmp(mime, "image/png") || !strcmp(mime, "image/jpeg"))
		return mime;
	const char *dot = strrchr(uri, '.');
	if (dot && !strcasecmp(dot, ".png"))
		return "image/png";
	if (dot && (!strcasecmp(dot, ".jpg") || !strcasecmp(dot, ".jpeg")))
		return "image/jpeg";
	return NULL;
}

/* Images with a uri: their bytes into the chunk, a bufferView each. */
static rad_status pack_images(packer *pk, json_t *root)
{
	json_t *images = json_object_get(root, "images");
	for (size_t i = 0; i < json_array_size(images); i++) {
		json_t *im = json_array_get(images, i);
		const char *uri = json_string_value(json_object_get(im, "uri"));
		if (!uri)
			continue;
		unsigned char *bytes = NULL;
		size_t len = 0;
		char mime[64];
		rad_status st = read_uri(pk, KIND_IMAGE, i, uri, 0, mime,
		                         sizeof(mime), &bytes, &len);
		const char *type = st ? NULL : mime_of(uri, mime);
		if (!st && !type)
			st = rad_fail(pk->err, RAD_ERR_UNSUPPORTED,
			              "image %zu: '%.80s' is neither PNG nor "
			              "JPEG",
			              i, uri);
		json_int_t view = 0;
		if (!st)
			st = sio_pack_add_view(pk, root, bytes, len, &view);
		free(bytes);
		if (st)
			return st;
		json_object_set_new(im, "bufferView", json_integer(view));
		json_object_set_new(im, "mimeType", json_string(type));
		/* Messages about the image name it: by its file when unnamed.
		 */
		if (!json_string_value(json_object_get(im, "name")))
			json_object_set_new(im, "name", json_string(uri));
		json_object_del(im, "uri");
	}
	return RAD_OK;
}

/*
 * Photometric files named by nodes (extras.luxrad_photometry: a path
 * beside the scene): their bytes into the chunk, the path replaced by
 * {"bufferView": n, "name": path}, which the importer reads.
 */
static rad_status pack_photometry(packer *pk, json_t *root)
{
	json_t *nodes = json_object_get(root, "nodes");
	for (size_t i = 0; i < json_array_size(nodes); i++) {
		json_t *node = json_array_get(nodes, i);
		json_t *ref = json_object_get(json_object_get(node, "extras"),
		                              SIO_PHOTOMETRY_EXTRA);
		const char *uri = json_string_value(ref);
		if (!uri)
			continue;
		unsigned char *bytes = NULL;
		size_t len = 0;
		char mime[64];
		json_int_t view = 0;
		rad_status st = read_uri(pk, KIND_NODE, i, uri, 0, mime,
		                         sizeof(mime), &bytes, &len);
		if (!st)
			st = sio_pack_add_view(pk, root, bytes, len, &view);
		free(bytes);
		if (st)
			return st;
		sio_pack_photometry_ref(node, view, uri);
	}
	return RAD_OK;
}

/* ------------------------------------------------------------------ GLB */

static void put32(unsigned char *p, uint32_t v)
{
	p[0] = (unsigned char)v;
	p[1] = (unsigned char)(v >> 8);
	p[2] = (unsigned char)(v >> 16);
	p[3] = (unsigned char)(v >> 24);
}

static rad_status write_glb(packer *pk, const char *json, unsigned char **glb,
                            size_t *glb_len)
{
	size_t nj = strlen(json), pj = (nj + 3) / 4 * 4;
	size_t pb = (pk->nbin + 3) / 4 * 4;
	size_t total = 12 + 8 + pj + (pk->nbin ? 8 + pb : 0);
	if (total > GLB_MAX)
		return rad_fail(pk->err, RAD_ERR_LIMIT,
		                "the packed scene would exceed 4 GiB, the GLB "
		                "limit");
	unsigned char *g = malloc(total);
	if (!g)
		return rad_fail(pk->err, RAD_ERR_NOMEM, "out of memory");
	memcpy(g, "glTF", 4);
	put32(g + 4, 2);
	put32(g + 8, (uint32_t)total);
	put32(g + 12, (uint32_t)pj);
	put32(g + 16, GLB_JSON);
	memcpy(g + 20, json, nj);
	memset(g + 20 + nj, ' ', pj - nj);
	if (pk->nbin) {
		unsigned char *b = g + 20 + pj;
		put32(b, (uint32_t)pb);
		put32(b + 4, GLB_BIN);
		memcpy(b + 8, pk->bin, pk->nbin);
		memset(b + 8 + pk->nbin, 0, pb - pk->nbin);
	}
	*glb = g;
	*glb_len = total;
	return RAD_OK;
}

/* sio_pack, and a GLB's repacking (pk->glb_bin), with luminaires. */
static rad_status pack_doc(packer pk, const unsigned char *json, size_t len,
                           const sio_luminaire *lum, size_t nlum,
                           unsigned char **glb, size_t *glb_len,
                           sio_pack_info *info, rad_error *err)
{
	const char *dir = pk.dir;
	json_error_t je;
	size_t *base = NULL;
	char *text = NULL;
	rad_status st;

	*glb = NULL;
	*glb_len = 0;
	if (!realpath(dir, pk.realdir))
		return rad_fail(err, RAD_ERR_IO, "scene folder '%s': %s", dir,
		                strerror(errno));
	json_t *root = json_loadb((const char *)json, len, 0, &je);
	if (!root)
		return rad_fail(err, RAD_ERR_INVALID,
		                "malformed glTF: line %d: %s", je.line,
		                je.text);
	if (!json_is_object(root)) {
		json_decref(root);
		return rad_fail(err, RAD_ERR_INVALID,
		                "not a glTF document: the top level is not an "
		                "object");
	}
	json_t *buffers = json_object_get(root, "buffers");
	size_t nbuffers = json_array_size(buffers);
	if ((st = pack_buffers(&pk, buffers, &base)) ||
	    (st = move_views(&pk, json_object_get(root, "bufferViews"), base,
	                     nbuffers)) ||
	    (st = pack_images(&pk, root)) ||
	    (st = pack_photometry(&pk, root)) ||
	    (st = sio_pack_luminaires(&pk, root, lum, nlum)))
		goto done;
	if (nbuffers || pk.nbin) {
		json_t *one = json_object();
		json_object_set_new(one, "byteLength",
		                    json_integer((json_int_t)pk.nbin));
		json_t *arr = json_array();
		json_array_append_new(arr, one);
		json_object_set_new(root, "buffers", arr);
	}
	text = json_dumps(root, JSON_COMPACT);
	if (!text) {
		st = rad_fail(err, RAD_ERR_NOMEM, "out of memory");
		goto done;
	}
	st = write_glb(&pk, text, glb, glb_len);
	if (!st && info)
		*info = pk.info;
done:
	free(text);
	free(base);
	free(pk.bin);
	json_decref(root);
	return st;
}

rad_status sio_pack(const unsigned char *json, size_t len, const char *dir,
                    unsigned char **glb, size_t *glb_len, sio_pack_info *info,
                    rad_error *err)
{
	packer pk = {.dir = dir, .err = err};
	return pack_doc(pk, json, len, NULL, 0, glb, glb_len, info, err);
}

rad_status sio_scene_read(const char *path, unsigned char **out, size_t *len,
                          sio_pack_info *info, rad_error *err)
{
	return sio_scene_read_lum(path, NULL, 0, out, len, info, err);
}

rad_status sio_scene_read_lum(const char *path, const sio_luminaire *lum,
                              size_t nlum, unsigned char **out, size_t *len,
                              sio_pack_info *info, rad_error *err)
{
	unsigned char *bytes;
	size_t n;
	if (info)
		memset(info, 0, sizeof(*info));
	rad_status st = sio_file_read(path, &bytes, &n, err);
	if (!st && sio_is_lfs_pointer(bytes, n)) {
		free(bytes);
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: the scene file is " SIO_LFS_HINT, path);
	}
	if (st || (sio_is_glb(bytes, n) && nlum == 0)) {
		*out = st ? NULL : bytes;
		*len = st ? 0 : n;
		return st;
	}
	char dir[PATH_MAX];
	const char *slash = strrchr(path, '/');
	if (!slash)
		snprintf(dir, sizeof(dir), ".");
	else if (slash == path)
		snprintf(dir, sizeof(dir), "/");
	else
		snprintf(dir, sizeof(dir), "%.*s", (int)(slash - path), path);
	packer pk = {.dir = dir, .err = err};
	const unsigned char *json = bytes;
	size_t njson = n;
	if (sio_is_glb(bytes, n)) /* luminaires to add: repack it */
		st = sio_glb_split(bytes, n, &json, &njson, &pk.glb_bin,
		                   &pk.nglb_bin, err);
	if (!st)
		st = pack_doc(pk, json, njson, lum, nlum, out, len, info, err);
	free(bytes);
	if (st && err) {
		/* Name the file: the pack's messages name only the part. */
		char why[sizeof(err->msg)];
		snprintf(why, sizeof(why), "%s", err->msg);
		rad_fail(err, st, "%s: %s", path, why);
	}
	return st;
}
