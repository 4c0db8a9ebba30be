/*
 * precheck.c -- what tinygltf 2.7.0 must not be shown: the raw bytes are
 * checked here before the shim hands them over.
 *
 *  - A GLB container whose BIN chunk declares a length running 8 bytes
 *    past the end of the data: tinygltf accepts it and reads those bytes.
 *    The whole container (header, JSON chunk, optional BIN chunk) is
 *    checked against the bytes received.
 *  - JSON nested thousands deep: tinygltf converts "extras" and
 *    "extensions" recursively and overflows the stack (30,000 levels, 60
 *    KB of brackets, are enough).  Bracket depth is counted outside
 *    strings; real glTF nests fewer than 10 levels.
 */

#include "internal.h"

#define GLB_JSON 0x4E4F534Au /* "JSON" read little-endian */
#define GLB_BIN 0x004E4942u  /* "BIN\0" */
#define MAX_JSON_DEPTH 64

static uint32_t rd32(const unsigned char *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
	       (uint32_t)p[3] << 24;
}

/* Check the GLB container (header, JSON chunk, optional BIN chunk). */
static rad_status check_glb(const unsigned char *b, size_t len, rad_error *err)
{
	if (len < 20)
		return rad_fail(err, RAD_ERR_INVALID,
		                "truncated GLB: %zu bytes, the header and the "
		                "JSON chunk header alone take 20",
		                len);
	if (rd32(b + 4) != 2)
		return rad_fail(
		        err, RAD_ERR_UNSUPPORTED,
		        "GLB container version %u (only 2 is supported)",
		        rd32(b + 4));
	if (rd32(b + 8) != len)
		return rad_fail(err, RAD_ERR_INVALID,
		                "GLB header gives a length of %u bytes but %zu "
		                "bytes were received",
		                rd32(b + 8), len);
	uint32_t jlen = rd32(b + 12);
	if (rd32(b + 16) != GLB_JSON || jlen == 0 || jlen % 4 != 0 ||
	    jlen > len - 20)
		return rad_fail(err, RAD_ERR_INVALID,
		                "GLB: the first chunk must be JSON, non-empty, "
		                "4-byte padded and inside the file (length %u, "
		                "file %zu bytes)",
		                jlen, len);
	size_t off = 20 + (size_t)jlen;
	if (off == len)
		return RAD_OK; /* no BIN chunk */
	if (len - off < 8)
		return rad_fail(err, RAD_ERR_INVALID,
		                "GLB: truncated chunk header at byte %zu", off);
	uint32_t blen = rd32(b + off);
	if (rd32(b + off + 4) != GLB_BIN || blen % 4 != 0 ||
	    blen > len - off - 8)
		return rad_fail(
		        err, RAD_ERR_INVALID,
		        "GLB: the chunk at byte %zu must be BIN, 4-byte "
		        "padded and inside the file (length %u)",
		        off, blen);
	return RAD_OK;
}

static rad_status check_depth(const unsigned char *p, size_t n, rad_error *err)
{
	int depth = 0, in_string = 0;
	for (size_t i = 0; i < n; i++) {
		if (in_string) {
			if (p[i] == '\\')
				i++; /* skip the escaped character */
			else if (p[i] == '"')
				in_string = 0;
		} else if (p[i] == '"') {
			in_string = 1;
		} else if (p[i] == '{' || p[i] == '[') {
			if (++depth > MAX_JSON_DEPTH)
				return rad_fail(err, RAD_ERR_INVALID,
				                "JSON nests deeper than %d "
				                "levels at byte %zu",
				                MAX_JSON_DEPTH, i);
		} else if (p[i] == '}' || p[i] == ']') {
			depth--;
		}
	}
	return RAD_OK;
}

rad_status sio_precheck(const unsigned char *b, size_t len, int *glb,
                        rad_error *err)
{
	*glb = sio_is_glb(b, len);
	if (!*glb)
		return check_depth(b, len, err);
	rad_status st = check_glb(b, len, err);
	return st != RAD_OK ? st : check_depth(b + 20, rd32(b + 12), err);
}
