/*
 * gltf.cc -- glTF 2.0 import and export: the one C++ file of luxrad and the
 * only one that sees tinygltf.
 *
 * Import turns untrusted bytes (from the network as much as from disk) into
 * a committed rad_scene.  tinygltf parses the JSON and decodes the buffers,
 * but checks little beyond JSON syntax, so everything it hands back is
 * treated as hostile: every index is range-checked and every accessor is
 * bounds-checked against its bufferView and buffer before a byte is read;
 * each failure names the object at fault.  Export builds a tinygltf::Model
 * from caller arrays and lets tinygltf serialize it.
 *
 * DESIGN
 *  - No exception crosses the C boundary: both entry points catch
 *    everything; std::bad_alloc becomes RAD_ERR_NOMEM.  On any failure the
 *    partial scene is freed.
 *  - tinygltf comes from the Debian shared library: no TINYGLTF_* defines
 *    here (they would break the ODR, see docs/PITFALLS.md).  Its filesystem
 *    callbacks are replaced by ones that refuse every path and its image
 *    loader by one that keeps nothing, so a document can neither make us
 *    read a file nor decode an image.
 *  - The GLB container is checked here before tinygltf sees it: 2.7.0
 *    accepts a BIN chunk whose declared length runs 8 bytes past the end of
 *    the data and then reads those bytes.
 *  - Transforms are composed and applied in double; triangles go to the
 *    builder in fixed-size batches.  Non-finite and degenerate triangles
 *    are passed through: the builder skips and counts them.
 *  - Materials: reflectance is baseColorFactor (linear RGB), whatever
 *    metallicFactor says (metals become diffuse reflectors: the engine has
 *    no specular transport); textures and alpha are ignored.  Reflectance is
 *    clamped to kMaxReflectance because rho = 1 in a closed room makes
 *    I - rho F singular.  Luminance is emissiveFactor x
 *    KHR_materials_emissive_strength (cd/m2).
 */
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include "sceneio.h"

extern "C" {
#include "err.h"
}

namespace
{

const double kMaxReflectance = 0.999; /* see the DESIGN note */
const size_t kBatchTriangles = 1024;  /* per rad_scene_add_triangles call */
const uint32_t kGlbJson = 0x4E4F534A; /* "JSON" read little-endian */
const uint32_t kGlbBin = 0x004E4942;  /* "BIN\0" */
const int kMaxJsonDepth = 64; /* real glTF nests < 10; see check_depth */
const char kLightsExt[] = "KHR_lights_punctual";
const char kStrengthExt[] = "KHR_materials_emissive_strength";
const char kSensorPrefix[] = "sensor:";      /* node name declaring one */
const char kSensorExtra[] = "luxrad_sensor"; /* or this key in extras */

/* ------------------------------------------------------------ messages */

/* Append a warning to info->warnings ("; "-separated, truncated). */
__attribute__((format(printf, 2, 3))) void note(sio_info *info, const char *fmt,
                                                ...)
{
	if (!info)
		return;
	size_t used = strlen(info->warnings);
	size_t cap = sizeof(info->warnings);
	if (used && used + 2 < cap) {
		memcpy(info->warnings + used, "; ", 3);
		used += 2;
	}
	if (used + 1 >= cap)
		return;
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(info->warnings + used, cap - used, fmt, ap);
	va_end(ap);
}

/* Put the glTF object's name in front of a builder message about it. */
rad_status blame(rad_error *err, rad_status st, const char *label)
{
	if (st != RAD_OK && err) {
		std::string msg = err->msg;
		rad_fail(err, st, "%s: %s", label, msg.c_str());
	}
	return st;
}

/* tinygltf messages are newline-separated lines; we want one line. */
std::string one_line(std::string s)
{
	while (!s.empty() && (s.back() == '\n' || s.back() == '\r'))
		s.pop_back();
	for (char &ch : s)
		if (ch == '\n' || ch == '\r')
			ch = ' ';
	return s;
}

const char *type_name(int type)
{
	switch (type) {
	case TINYGLTF_TYPE_SCALAR:
		return "SCALAR";
	case TINYGLTF_TYPE_VEC2:
		return "VEC2";
	case TINYGLTF_TYPE_VEC3:
		return "VEC3";
	case TINYGLTF_TYPE_VEC4:
		return "VEC4";
	default:
		return "a matrix type";
	}
}

/* --------------------------------------------------- parsing (tinygltf) */

/* Filesystem callbacks that refuse every path; remembers the first one. */
struct Refusal {
	bool asked = false; /* tinygltf looked for a file */
	std::string path;   /* the first path asked for (after urldecode) */
};

bool fs_exists(const std::string &path, void *ud)
{
	Refusal *r = static_cast<Refusal *>(ud);
	if (!r->asked)
		r->path = path;
	r->asked = true;
	return false;
}

std::string fs_expand(const std::string &path, void *)
{
	return path;
}

/* Never reached (fs_exists says no) but tinygltf wants all four set. */
bool fs_read(std::vector<unsigned char> *, std::string *e, const std::string &,
             void *)
{
	if (e)
		*e = "file access is disabled";
	return false;
}

bool fs_write(std::string *e, const std::string &,
              const std::vector<unsigned char> &, void *)
{
	if (e)
		*e = "file access is disabled";
	return false;
}

/* Textures are ignored: keep no pixels, report success. */
bool skip_image(tinygltf::Image *, const int, std::string *, std::string *, int,
                int, const unsigned char *, int, void *)
{
	return true;
}

uint32_t rd32(const unsigned char *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
	       (uint32_t)p[3] << 24;
}

/* Check the GLB container (header, JSON chunk, optional BIN chunk). */
rad_status check_glb(const unsigned char *b, size_t len, rad_error *err)
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
	if (rd32(b + 16) != kGlbJson || jlen == 0 || jlen % 4 != 0 ||
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
	if (rd32(b + off + 4) != kGlbBin || blen % 4 != 0 ||
	    blen > len - off - 8)
		return rad_fail(
		        err, RAD_ERR_INVALID,
		        "GLB: the chunk at byte %zu must be BIN, 4-byte "
		        "padded and inside the file (length %u)",
		        off, blen);
	return RAD_OK;
}

/*
 * tinygltf converts "extras" and "extensions" recursively and crashes on
 * deep nesting (30,000 levels, 60 KB of brackets, overflow the stack).
 * Count bracket depth outside strings before it sees the text.
 */
rad_status check_depth(const unsigned char *p, size_t n, rad_error *err)
{
	int depth = 0;
	bool in_string = false;
	for (size_t i = 0; i < n; i++) {
		if (in_string) {
			if (p[i] == '\\')
				i++; /* skip the escaped character */
			else if (p[i] == '"')
				in_string = false;
		} else if (p[i] == '"') {
			in_string = true;
		} else if (p[i] == '{' || p[i] == '[') {
			if (++depth > kMaxJsonDepth)
				return rad_fail(err, RAD_ERR_INVALID,
				                "JSON nests deeper than %d "
				                "levels at byte %zu",
				                kMaxJsonDepth, i);
		} else if (p[i] == '}' || p[i] == ']') {
			depth--;
		}
	}
	return RAD_OK;
}

/* Turn a tinygltf failure into a message that names the object. */
rad_status parse_failed(const std::string &msg, const Refusal &r,
                        const tinygltf::Model &m, rad_error *err)
{
	/* Buffers are parsed first and in order, and a failed one is not
	 * appended: the failing buffer's index is the number parsed. */
	size_t buf = m.buffers.size();
	if (msg.find("File not found") != std::string::npos) {
		if (r.path.empty())
			return rad_fail(err, RAD_ERR_INVALID,
			                "buffer %zu has no uri (only a GLB's "
			                "first buffer may omit it)",
			                buf);
		return rad_fail(err, RAD_ERR_INVALID,
		                "buffer %zu: external URI '%.80s%s' refused: "
		                "only data: URIs and the GLB binary chunk are "
		                "read",
		                buf, r.path.c_str(),
		                r.path.size() > 80 ? "..." : "");
	}
	if (msg.find("Failed to decode 'uri'") != std::string::npos)
		return rad_fail(err, RAD_ERR_INVALID,
		                "buffer %zu: the data: URI does not decode to "
		                "byteLength bytes",
		                buf);
	if (msg.find("Spot light description not found") != std::string::npos)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s light %zu: type \"spot\" requires a "
		                "\"spot\" object",
		                kLightsExt, m.lights.size());
	return rad_fail(err, RAD_ERR_INVALID, "malformed glTF: %s",
	                one_line(msg).c_str());
}

rad_status parse(const unsigned char *b, size_t len, tinygltf::Model &m,
                 sio_info *info, rad_error *err)
{
	bool glb = len >= 4 && memcmp(b, "glTF", 4) == 0;
	rad_status st = glb ? check_glb(b, len, err) : RAD_OK;
	if (st == RAD_OK)
		st = glb ? check_depth(b + 20, rd32(b + 12), err)
		         : check_depth(b, len, err);
	if (st != RAD_OK)
		return st;
	Refusal refusal;
	tinygltf::TinyGLTF loader;
	loader.SetFsCallbacks(tinygltf::FsCallbacks{
	        fs_exists, fs_expand, fs_read, fs_write, &refusal});
	loader.SetImageLoader(skip_image, nullptr);
	std::string terr, twarn;
	bool ok = glb ? loader.LoadBinaryFromMemory(&m, &terr, &twarn, b,
	                                            (unsigned)len, "")
	              : loader.LoadASCIIFromString(
	                        &m, &terr, &twarn,
	                        reinterpret_cast<const char *>(b),
	                        (unsigned)len, "");
	if (!twarn.empty())
		note(info, "%s", one_line(twarn).c_str());
	if (!ok)
		return parse_failed(terr, refusal, m, err);
	return RAD_OK;
}

/* Refuse documents that need an extension we do not implement. */
rad_status check_required(const tinygltf::Model &m, rad_error *err)
{
	for (const std::string &ext : m.extensionsRequired)
		if (ext != kLightsExt && ext != kStrengthExt)
			return rad_fail(err, RAD_ERR_UNSUPPORTED,
			                "extensionsRequired: '%s' is not "
			                "supported",
			                ext.c_str());
	return RAD_OK;
}

/* Fill the info counters that depend on the materials alone. */
void count_materials(const tinygltf::Model &m, sio_info *info)
{
	if (!info)
		return;
	for (const tinygltf::Material &mat : m.materials) {
		const tinygltf::PbrMetallicRoughness &pbr =
		        mat.pbrMetallicRoughness;
		info->textures_ignored +=
		        (pbr.baseColorTexture.index >= 0) +
		        (pbr.metallicRoughnessTexture.index >= 0) +
		        (mat.normalTexture.index >= 0) +
		        (mat.occlusionTexture.index >= 0) +
		        (mat.emissiveTexture.index >= 0);
		info->metallic_materials += pbr.metallicFactor > 0;
	}
}

/* ---------------------------------------------------------- transforms */

struct Mat4 {
	double m[16]; /* column-major like glTF: m[col * 4 + row] */
};

Mat4 mat_identity()
{
	Mat4 r = {};
	r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1;
	return r;
}

Mat4 mat_mul(const Mat4 &a, const Mat4 &b)
{
	Mat4 r;
	for (int c = 0; c < 4; c++)
		for (int row = 0; row < 4; row++) {
			double s = 0;
			for (int k = 0; k < 4; k++)
				s += a.m[k * 4 + row] * b.m[c * 4 + k];
			r.m[c * 4 + row] = s;
		}
	return r;
}

/* Determinant of the linear part; its sign tells whether winding flips. */
double mat_det3(const Mat4 &a)
{
	const double *x = a.m, *y = a.m + 4, *z = a.m + 8;
	return x[0] * (y[1] * z[2] - y[2] * z[1]) -
	       x[1] * (y[0] * z[2] - y[2] * z[0]) +
	       x[2] * (y[0] * z[1] - y[1] * z[0]);
}

/* The bottom row is ignored: glTF matrices must be affine (TRS). */
void mat_point(const Mat4 &a, const float p[3], double out[3])
{
	for (int r = 0; r < 3; r++)
		out[r] = a.m[r] * p[0] + a.m[4 + r] * p[1] + a.m[8 + r] * p[2] +
		         a.m[12 + r];
}

/* Everything one import needs while it walks the document. */
struct Loader {
	const tinygltf::Model &m;
	rad_scene *s;
	sio_info *info;               /* may be NULL */
	rad_error *err;               /* may be NULL */
	std::vector<int64_t> mat_ids; /* [glTF material + 1]: id, or -1 */
	std::vector<double> batch;    /* triangles waiting for the builder */
	uint64_t triangles;           /* offered so far (counts are 32-bit) */
	/* sio_sensors: collect sensor nodes here instead of building */
	std::vector<sio_sensor> *sensors = nullptr;
	std::map<std::string, int> sensor_node{}; /* name -> declaring node */
};

const char *node_name(const Loader &L, int ni)
{
	return L.m.nodes[(size_t)ni].name.c_str();
}

/* Local transform of a node from its matrix, or T * R * S. */
rad_status node_local(const Loader &L, int ni, Mat4 *out)
{
	const tinygltf::Node &n = L.m.nodes[(size_t)ni];
	*out = mat_identity();
	if (!n.matrix.empty()) {
		if (n.matrix.size() != 16)
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "node %d '%s': matrix has %zu numbers, "
			                "expected 16",
			                ni, node_name(L, ni), n.matrix.size());
		std::copy(n.matrix.begin(), n.matrix.end(), out->m);
		return RAD_OK;
	}
	if ((!n.translation.empty() && n.translation.size() != 3) ||
	    (!n.rotation.empty() && n.rotation.size() != 4) ||
	    (!n.scale.empty() && n.scale.size() != 3))
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "node %d '%s': translation, rotation and scale "
		                "need 3, 4 and 3 numbers",
		                ni, node_name(L, ni));
	double q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
	if (!n.rotation.empty()) {
		double len = std::sqrt(n.rotation[0] * n.rotation[0] +
		                       n.rotation[1] * n.rotation[1] +
		                       n.rotation[2] * n.rotation[2] +
		                       n.rotation[3] * n.rotation[3]);
		if (!(len > 0) || !std::isfinite(len))
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "node %d '%s': rotation is not a "
			                "usable quaternion",
			                ni, node_name(L, ni));
		for (int k = 0; k < 4; k++)
			q[k] = n.rotation[(size_t)k] / len;
	}
	if (!n.scale.empty())
		std::copy(n.scale.begin(), n.scale.end(), s);
	const double x = q[0], y = q[1], z = q[2], w = q[3];
	const double r[3][3] = {
	        {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),
	         2 * (x * z + y * w)},
	        {2 * (x * y + z * w), 1 - 2 * (x * x + z * z),
	         2 * (y * z - x * w)},
	        {2 * (x * z - y * w), 2 * (y * z + x * w),
	         1 - 2 * (x * x + y * y)},
	};
	for (int c = 0; c < 3; c++)
		for (int row = 0; row < 3; row++)
			out->m[c * 4 + row] = r[row][c] * s[c];
	for (size_t k = 0; k < n.translation.size(); k++)
		out->m[12 + k] = n.translation[k];
	return RAD_OK;
}

/* A node that places geometry or a light needs a usable world matrix. */
rad_status check_world(const Loader &L, int ni, const Mat4 &w)
{
	for (double v : w.m)
		if (!std::isfinite(v))
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "node %d '%s': world transform is not "
			                "finite",
			                ni, node_name(L, ni));
	double det = mat_det3(w);
	if (!std::isfinite(det))
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "node %d '%s': world transform overflows "
		                "(determinant not finite)",
		                ni, node_name(L, ni));
	if (det == 0)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "node %d '%s': world transform is singular "
		                "(determinant 0)",
		                ni, node_name(L, ni));
	return RAD_OK;
}

/* ----------------------------------------------------------- accessors */

/* An accessor resolved to bytes; every element lies inside its buffer. */
struct View {
	const unsigned char *p; /* first element */
	size_t stride;          /* bytes between elements */
	size_t count;           /* elements */
	size_t size;            /* bytes per element read */
};

/*
 * Resolve accessor ai (already range-checked) whose elements are elem
 * bytes.  where/role name it in messages ("mesh 2 'Chair' primitive 0",
 * "index accessor").  Alignment is not enforced: elements are read with
 * memcpy.
 */
rad_status accessor_view(const Loader &L, const char *where, const char *role,
                         int ai, size_t elem, View *v)
{
	const tinygltf::Accessor &a = L.m.accessors[(size_t)ai];
	if (a.sparse.isSparse)
		return rad_fail(L.err, RAD_ERR_UNSUPPORTED,
		                "%s: %s %d is sparse (not supported)", where,
		                role, ai);
	if (a.bufferView < 0)
		return rad_fail(L.err, RAD_ERR_UNSUPPORTED,
		                "%s: %s %d has no bufferView (zero-filled "
		                "accessors are not supported)",
		                where, role, ai);
	if ((size_t)a.bufferView >= L.m.bufferViews.size())
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: %s %d: bufferView %d out of range (%zu "
		                "bufferViews)",
		                where, role, ai, a.bufferView,
		                L.m.bufferViews.size());
	const tinygltf::BufferView &bv = L.m.bufferViews[(size_t)a.bufferView];
	if (bv.buffer < 0 || (size_t)bv.buffer >= L.m.buffers.size())
		return rad_fail(
		        L.err, RAD_ERR_INVALID,
		        "%s: bufferView %d: buffer %d out of range (%zu "
		        "buffers)",
		        where, a.bufferView, bv.buffer, L.m.buffers.size());
	const std::vector<unsigned char> &data =
	        L.m.buffers[(size_t)bv.buffer].data;
	if (bv.byteOffset > data.size() ||
	    bv.byteLength > data.size() - bv.byteOffset)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: bufferView %d (offset %zu, length %zu) "
		                "runs past the end of buffer %d (%zu bytes)",
		                where, a.bufferView, bv.byteOffset,
		                bv.byteLength, bv.buffer, data.size());
	size_t stride = bv.byteStride ? bv.byteStride : elem;
	if (stride < elem)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: bufferView %d: byteStride %zu is smaller "
		                "than one element of %s %d (%zu bytes)",
		                where, a.bufferView, stride, role, ai, elem);
	if (a.count == 0)
		return rad_fail(L.err, RAD_ERR_INVALID, "%s: %s %d is empty",
		                where, role, ai);
	/* Overflow-safe form of offset + (count - 1) * stride + elem <= len */
	size_t avail = bv.byteLength;
	if (a.byteOffset > avail || elem > avail - a.byteOffset ||
	    a.count - 1 > (avail - a.byteOffset - elem) / stride)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: %s %d (offset %zu, count %zu, stride %zu) "
		                "reads past the end of bufferView %d (%zu "
		                "bytes)",
		                where, role, ai, a.byteOffset, a.count, stride,
		                a.bufferView, avail);
	v->p = data.data() + bv.byteOffset + a.byteOffset;
	v->stride = stride;
	v->count = a.count;
	v->size = elem;
	return RAD_OK;
}

/* Read POSITION (VEC3 float) and transform it to world space. */
rad_status load_positions(const Loader &L, const char *where, int ai,
                          const Mat4 &w, std::vector<double> *out)
{
	if (ai < 0 || (size_t)ai >= L.m.accessors.size())
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: POSITION accessor %d out of range (%zu "
		                "accessors)",
		                where, ai, L.m.accessors.size());
	const tinygltf::Accessor &a = L.m.accessors[(size_t)ai];
	if (a.type != TINYGLTF_TYPE_VEC3 ||
	    a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: POSITION accessor %d must be VEC3 of "
		                "FLOAT (componentType 5126), not %s of "
		                "componentType %d",
		                where, ai, type_name(a.type), a.componentType);
	View v;
	rad_status st =
	        accessor_view(L, where, "POSITION accessor", ai, 12, &v);
	if (st != RAD_OK)
		return st;
	out->resize(3 * v.count);
	for (size_t i = 0; i < v.count; i++) {
		float p[3];
		memcpy(p, v.p + i * v.stride, sizeof p);
		mat_point(w, p, out->data() + 3 * i);
	}
	return RAD_OK;
}

/* Resolve an index accessor: SCALAR of u8, u16 or u32. */
rad_status index_view(const Loader &L, const char *where, int ai, View *v)
{
	if (ai < 0 || (size_t)ai >= L.m.accessors.size())
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: index accessor %d out of range (%zu "
		                "accessors)",
		                where, ai, L.m.accessors.size());
	const tinygltf::Accessor &a = L.m.accessors[(size_t)ai];
	size_t size = 0;
	switch (a.componentType) {
	case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
		size = 1;
		break;
	case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
		size = 2;
		break;
	case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
		size = 4;
		break;
	}
	if (a.type != TINYGLTF_TYPE_SCALAR || size == 0)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: index accessor %d must be SCALAR of "
		                "unsigned byte, short or int, not %s of "
		                "componentType %d",
		                where, ai, type_name(a.type), a.componentType);
	return accessor_view(L, where, "index accessor", ai, size, v);
}

/* Element k of an index view (glTF data is little-endian, as is x86). */
size_t index_at(const View &v, size_t k)
{
	const unsigned char *p = v.p + k * v.stride;
	if (v.size == 1)
		return p[0];
	if (v.size == 2) {
		uint16_t x;
		memcpy(&x, p, 2);
		return x;
	}
	uint32_t x;
	memcpy(&x, p, 4);
	return x;
}

/* Corners of triangle t of a list, strip or fan (glTF spec, 3.7.2.1). */
void corners(int mode, size_t t, size_t c[3])
{
	if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
		c[0] = t;
		c[1] = t + 1 + t % 2;
		c[2] = t + 2 - t % 2;
	} else if (mode == TINYGLTF_MODE_TRIANGLE_FAN) {
		c[0] = t + 1;
		c[1] = t + 2;
		c[2] = 0;
	} else {
		c[0] = 3 * t;
		c[1] = 3 * t + 1;
		c[2] = 3 * t + 2;
	}
}

rad_status flush(Loader &L, uint32_t mat, uint32_t node)
{
	size_t n = L.batch.size() / 9;
	if (n == 0)
		return RAD_OK;
	rad_status st = rad_scene_add_triangles(L.s, mat, node, L.batch.data(),
	                                        n, L.err);
	L.batch.clear();
	return st;
}

/* One primitive's geometry. */
struct Prim {
	const char *where;       /* "mesh 2 'Chair' primitive 0" */
	int mode;                /* TRIANGLES, STRIP or FAN */
	std::vector<double> pos; /* world-space vertices, 3 doubles each */
	const View *idx;         /* NULL when not indexed */
	bool flip;               /* the world matrix mirrors: swap corners */
	uint32_t mat, node;      /* rad_scene ids */
};

/* Assemble the triangles of a primitive and hand them to the builder. */
rad_status emit_triangles(Loader &L, const Prim &p)
{
	size_t nv = p.pos.size() / 3, n = p.idx ? p.idx->count : nv, ntri;
	if (p.mode == TINYGLTF_MODE_TRIANGLES) {
		if (n % 3 != 0)
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "%s: %zu %s is not a multiple of 3",
			                p.where, n,
			                p.idx ? "indices" : "vertices");
		ntri = n / 3;
	} else {
		ntri = n >= 3 ? n - 2 : 0;
	}
	if (ntri > UINT32_MAX - L.triangles)
		return rad_fail(L.err, RAD_ERR_LIMIT,
		                "%s: the scene would exceed %u triangles",
		                p.where, UINT32_MAX);
	L.triangles += ntri;
	for (size_t t = 0; t < ntri; t++) {
		size_t c[3], v[3];
		corners(p.mode, t, c);
		for (int k = 0; k < 3; k++) {
			v[k] = p.idx ? index_at(*p.idx, c[k]) : c[k];
			if (v[k] >= nv)
				return rad_fail(L.err, RAD_ERR_INVALID,
				                "%s: index %zu (at position "
				                "%zu) >= vertex count %zu",
				                p.where, v[k], c[k], nv);
		}
		if (p.flip)
			std::swap(v[1], v[2]);
		for (int k = 0; k < 3; k++)
			L.batch.insert(L.batch.end(), &p.pos[3 * v[k]],
			               &p.pos[3 * v[k]] + 3);
		if (L.batch.size() == 9 * kBatchTriangles) {
			rad_status st = flush(L, p.mat, p.node);
			if (st != RAD_OK)
				return st;
		}
	}
	return flush(L, p.mat, p.node);
}

/* --------------------------------------------------------- materials */

/* KHR_materials_emissive_strength.emissiveStrength, default 1. */
rad_status emissive_strength(const Loader &L, const tinygltf::Material &mat,
                             const char *label, double *out)
{
	*out = 1;
	auto it = mat.extensions.find(kStrengthExt);
	if (it == mat.extensions.end() || !it->second.Has("emissiveStrength"))
		return RAD_OK;
	const tinygltf::Value &v = it->second.Get("emissiveStrength");
	if (!v.IsNumber() || !(v.GetNumberAsDouble() >= 0))
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: %s.emissiveStrength must be a number >= 0",
		                label, kStrengthExt);
	*out = v.GetNumberAsDouble();
	return RAD_OK;
}

/* Reflectance and luminance of glTF material mi (>= 0), unclamped. */
rad_status material_values(const Loader &L, int mi, const char *label,
                           double rho[3], double lum[3])
{
	const tinygltf::Material &mat = L.m.materials[(size_t)mi];
	/* tinygltf guarantees 4 and 3 numbers (defaults when absent). */
	const std::vector<double> &bc =
	        mat.pbrMetallicRoughness.baseColorFactor;
	const std::vector<double> &ef = mat.emissiveFactor;
	double strength;
	rad_status st = emissive_strength(L, mat, label, &strength);
	if (st != RAD_OK)
		return st;
	for (size_t c = 0; c < 3; c++) {
		if (!(bc[c] >= 0) || !(ef[c] >= 0))
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "%s: negative baseColorFactor or "
			                "emissiveFactor",
			                label);
		rho[c] = bc[c];
		lum[c] = ef[c] * strength;
	}
	return RAD_OK;
}

/* rad_scene material id of glTF material mi (-1: the glTF default). */
rad_status material_id(Loader &L, int mi, const char *where, uint32_t *id)
{
	if (mi < -1 || mi >= (int64_t)L.m.materials.size())
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: material %d out of range (%zu materials)",
		                where, mi, L.m.materials.size());
	int64_t &slot = L.mat_ids[(size_t)(mi + 1)];
	if (slot >= 0) {
		*id = (uint32_t)slot;
		return RAD_OK;
	}
	char label[192];
	double rho[3] = {1, 1, 1}, lum[3] = {0, 0, 0}; /* glTF default */
	if (mi < 0) {
		snprintf(label, sizeof label, "default material");
	} else {
		snprintf(label, sizeof label, "material %d '%s'", mi,
		         L.m.materials[(size_t)mi].name.c_str());
		rad_status st = material_values(L, mi, label, rho, lum);
		if (st != RAD_OK)
			return st;
	}
	bool clamped = false;
	for (double &r : rho)
		if (r > kMaxReflectance) {
			r = kMaxReflectance;
			clamped = true;
		}
	if (clamped)
		note(L.info, "%s: reflectance clamped to %g", label,
		     kMaxReflectance);
	uint32_t u;
	rad_status st = blame(
	        L.err, rad_scene_add_material(L.s, rho, lum, &u, L.err), label);
	if (st != RAD_OK)
		return st;
	slot = u;
	*id = u;
	return RAD_OK;
}

/* ------------------------------------------------------------- meshes */

rad_status add_primitive(Loader &L, int mi, size_t pi, const Mat4 &w,
                         uint32_t node)
{
	const tinygltf::Mesh &mesh = L.m.meshes[(size_t)mi];
	const tinygltf::Primitive &gp = mesh.primitives[pi];
	char where[192];
	snprintf(where, sizeof where, "mesh %d '%s' primitive %zu", mi,
	         mesh.name.c_str(), pi);
	if (gp.mode < TINYGLTF_MODE_POINTS ||
	    gp.mode > TINYGLTF_MODE_TRIANGLE_FAN)
		return rad_fail(L.err, RAD_ERR_INVALID, "%s: unknown mode %d",
		                where, gp.mode);
	if (gp.mode < TINYGLTF_MODE_TRIANGLES) { /* points and lines */
		if (L.info)
			L.info->primitives_skipped++;
		return RAD_OK;
	}
	auto pos = gp.attributes.find("POSITION");
	if (pos == gp.attributes.end())
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "%s: no POSITION attribute", where);
	Prim p = {where, gp.mode, {}, nullptr, mat_det3(w) < 0, 0, node};
	rad_status st = load_positions(L, where, pos->second, w, &p.pos);
	View idx;
	if (st == RAD_OK && gp.indices != -1) {
		st = index_view(L, where, gp.indices, &idx);
		p.idx = &idx;
	}
	if (st == RAD_OK)
		st = material_id(L, gp.material, where, &p.mat);
	if (st == RAD_OK)
		st = emit_triangles(L, p);
	if (st == RAD_OK && L.info)
		L.info->primitives++;
	return st;
}

/* One rad_scene node per glTF node that carries a mesh. */
rad_status add_mesh_node(Loader &L, int ni, const Mat4 &w)
{
	const tinygltf::Node &n = L.m.nodes[(size_t)ni];
	if (n.mesh < 0 || (size_t)n.mesh >= L.m.meshes.size())
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "node %d '%s': mesh %d out of range (%zu "
		                "meshes)",
		                ni, node_name(L, ni), n.mesh,
		                L.m.meshes.size());
	const tinygltf::Mesh &mesh = L.m.meshes[(size_t)n.mesh];
	std::string name = !n.name.empty()      ? n.name
	                   : !mesh.name.empty() ? mesh.name
	                                        : "node" + std::to_string(ni);
	uint32_t id;
	rad_status st = rad_scene_add_node(L.s, name.c_str(), &id, L.err);
	for (size_t pi = 0; st == RAD_OK && pi < mesh.primitives.size(); pi++)
		st = add_primitive(L, n.mesh, pi, w, id);
	return st;
}

/* -------------------------------------------------------------- lights */

/* Index of the KHR_lights_punctual light node ni carries, or -1. */
rad_status node_light(const Loader &L, int ni, int *li)
{
	const tinygltf::Node &n = L.m.nodes[(size_t)ni];
	*li = -1;
	auto it = n.extensions.find(kLightsExt);
	if (it == n.extensions.end())
		return RAD_OK;
	/* Value::Get asserts on non-objects: Has() checks that first. */
	const tinygltf::Value &v = it->second;
	double x = v.Has("light") && v.Get("light").IsNumber()
	                   ? v.Get("light").GetNumberAsDouble()
	                   : -1;
	if (!(x >= 0 && x < (double)L.m.lights.size()) || x != std::floor(x))
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "node %d '%s': %s.light must be the index of "
		                "one of the %zu lights",
		                ni, node_name(L, ni), kLightsExt,
		                L.m.lights.size());
	*li = (int)x;
	return RAD_OK;
}

/* Kind, intensity, range and cone of light li, checked. */
rad_status light_values(const Loader &L, int li, rad_light_desc *d)
{
	const tinygltf::Light &g = L.m.lights[(size_t)li];
	const char *name = g.name.c_str();
	if (g.type == "point")
		d->kind = RAD_LIGHT_POINT;
	else if (g.type == "spot")
		d->kind = RAD_LIGHT_SPOT;
	else if (g.type == "directional")
		d->kind = RAD_LIGHT_DIRECTIONAL;
	else
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "light %d '%s': unknown type '%s'", li, name,
		                g.type.c_str());
	if (!g.color.empty() && g.color.size() != 3)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "light %d '%s': color has %zu numbers, "
		                "expected 3",
		                li, name, g.color.size());
	for (size_t c = 0; c < 3; c++) {
		double col = g.color.empty() ? 1 : g.color[c]; /* white */
		d->intensity[c] = col * g.intensity;
		if (!(col >= 0) || !(g.intensity >= 0))
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "light %d '%s': negative color or "
			                "intensity",
			                li, name);
	}
	d->range = g.range; /* 0 (absent) = infinite */
	d->inner_cone = g.spot.innerConeAngle;
	d->outer_cone = g.spot.outerConeAngle;
	if (!(g.range >= 0) ||
	    (d->kind == RAD_LIGHT_SPOT &&
	     !(d->inner_cone >= 0 && d->inner_cone < d->outer_cone &&
	       d->outer_cone <= M_PI / 2)))
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "light %d '%s': needs range >= 0 and, for a "
		                "spot, 0 <= innerConeAngle < outerConeAngle "
		                "<= pi/2",
		                li, name);
	return RAD_OK;
}

/* A light placed by node ni: lights shine down their local -Z. */
rad_status add_light(Loader &L, int ni, int li, const Mat4 &w)
{
	rad_light_desc d = {};
	rad_status st = light_values(L, li, &d);
	if (st != RAD_OK)
		return st;
	double len = std::sqrt(w.m[8] * w.m[8] + w.m[9] * w.m[9] +
	                       w.m[10] * w.m[10]); /* > 0: w is regular */
	for (int k = 0; k < 3; k++) {
		d.position[k] = w.m[12 + k];
		d.direction[k] = -w.m[8 + k] / len;
	}
	const std::string &lname = L.m.lights[(size_t)li].name;
	d.name = !lname.empty() ? lname.c_str() : node_name(L, ni);
	char label[192];
	snprintf(label, sizeof label, "node %d '%s'", ni, node_name(L, ni));
	return blame(L.err, rad_scene_add_light(L.s, &d, L.err), label);
}

/* ------------------------------------------------------------- sensors */

/* The sensor name node ni declares ("" = none), checked. */
rad_status sensor_name(const Loader &L, int ni, std::string *name)
{
	const tinygltf::Node &n = L.m.nodes[(size_t)ni];
	const size_t plen = sizeof kSensorPrefix - 1;
	bool named = n.name.compare(0, plen, kSensorPrefix) == 0;
	bool tagged = n.extras.IsObject() && n.extras.Has(kSensorExtra);
	std::string by_name = named ? n.name.substr(plen) : std::string();
	if (tagged) {
		const tinygltf::Value &v = n.extras.Get(kSensorExtra);
		if (!v.IsString())
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "node %d '%s': extras.%s must be a "
			                "string (the sensor's name)",
			                ni, node_name(L, ni), kSensorExtra);
		*name = v.Get<std::string>();
		if (named && by_name != *name)
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "node %d '%s': declares sensor '%s' by "
			                "its name and '%s' in extras.%s",
			                ni, node_name(L, ni), by_name.c_str(),
			                name->c_str(), kSensorExtra);
	} else {
		*name = by_name;
	}
	if ((named || tagged) && name->empty())
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "node %d '%s': empty sensor name", ni,
		                node_name(L, ni));
	if (name->size() >= SIO_SENSOR_NAME_MAX)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "node %d: sensor name of %zu bytes (at most "
		                "%d)",
		                ni, name->size(), SIO_SENSOR_NAME_MAX - 1);
	for (unsigned char ch : *name)
		if (ch < 0x20 || ch == 0x7F)
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "node %d: sensor name has a control "
			                "character",
			                ni);
	return RAD_OK;
}

/* A sensor at the node's origin, facing its +Y axis (glTF's up). */
rad_status visit_sensor(Loader &L, int ni, const Mat4 &w)
{
	std::string name;
	rad_status st = sensor_name(L, ni, &name);
	if (st != RAD_OK || name.empty())
		return st;
	sio_sensor g = {};
	memcpy(g.name, name.c_str(), name.size() + 1);
	g.node = (uint32_t)ni;
	/* Scaled by the largest component first: a huge but finite axis
	 * must not overflow into an infinite length. */
	double big = std::max(std::fabs(w.m[4]),
	                      std::max(std::fabs(w.m[5]), std::fabs(w.m[6])));
	double len = 0;
	for (int k = 0; k < 3; k++) {
		g.position[k] = w.m[12 + k];
		if (!std::isfinite(g.position[k]))
			return rad_fail(
			        L.err, RAD_ERR_INVALID,
			        "sensor '%s' (node %d): position is not "
			        "finite",
			        g.name, ni);
		g.normal[k] = big > 0 ? w.m[4 + k] / big : 0;
		len += g.normal[k] * g.normal[k];
	}
	if (!(big > 0) || !std::isfinite(big))
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "sensor '%s' (node %d): normal (the node's +Y "
		                "axis in world space) is %s",
		                g.name, ni, big == 0 ? "zero" : "not finite");
	len = std::sqrt(len);
	for (double &c : g.normal)
		c /= len;
	auto seen = L.sensor_node.emplace(name, ni);
	if (!seen.second)
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "sensor '%s' declared twice (nodes %d and %d)",
		                g.name, seen.first->second, ni);
	L.sensors->push_back(g);
	return RAD_OK;
}

/* ------------------------------------------------------------- scenes */

rad_status visit_node(Loader &L, int ni, const Mat4 &w)
{
	if (L.sensors)
		return visit_sensor(L, ni, w);
	int li;
	rad_status st = node_light(L, ni, &li);
	if (L.info)
		L.info->nodes++;
	bool has_mesh = L.m.nodes[(size_t)ni].mesh != -1;
	if (st != RAD_OK || (!has_mesh && li < 0))
		return st;
	/* Pure grouping nodes are not checked: their transform only matters
	 * through descendants, which are. */
	st = check_world(L, ni, w);
	if (st == RAD_OK && has_mesh)
		st = add_mesh_node(L, ni, w);
	if (st == RAD_OK && li >= 0)
		st = add_light(L, ni, li, w);
	return st;
}

/* Roots to walk: the default scene, else scene 0, else every root node. */
rad_status scene_roots(const Loader &L, std::vector<int> *roots)
{
	const tinygltf::Model &m = L.m;
	int sc = m.defaultScene;
	if (sc < -1 || (sc >= 0 && (size_t)sc >= m.scenes.size()))
		return rad_fail(L.err, RAD_ERR_INVALID,
		                "default scene %d out of range (%zu scenes)",
		                sc, m.scenes.size());
	if (sc == -1 && !m.scenes.empty())
		sc = 0;
	if (sc >= 0) {
		for (int ni : m.scenes[(size_t)sc].nodes) {
			if (ni < 0 || (size_t)ni >= m.nodes.size())
				return rad_fail(L.err, RAD_ERR_INVALID,
				                "scene %d: node %d out of "
				                "range (%zu nodes)",
				                sc, ni, m.nodes.size());
			roots->push_back(ni);
		}
		return RAD_OK;
	}
	std::vector<char> child(m.nodes.size(), 0);
	for (const tinygltf::Node &n : m.nodes)
		for (int c : n.children)
			if (c >= 0 && (size_t)c < m.nodes.size())
				child[(size_t)c] = 1;
	for (size_t ni = 0; ni < m.nodes.size(); ni++)
		if (!child[ni])
			roots->push_back((int)ni);
	return RAD_OK;
}

/*
 * Depth-first walk with an explicit stack (a hostile document may nest
 * nodes deeper than the C stack allows).  A node met twice means a cycle
 * or a shared child: glTF requires the hierarchy to be a forest.
 */
rad_status walk_scene(Loader &L)
{
	struct Item {
		int node;
		Mat4 parent;
	};
	std::vector<int> roots;
	rad_status st = scene_roots(L, &roots);
	std::vector<char> seen(L.m.nodes.size(), 0);
	std::vector<Item> stack;
	for (size_t k = roots.size(); k-- > 0;)
		stack.push_back({roots[k], mat_identity()});
	while (st == RAD_OK && !stack.empty()) {
		Item it = stack.back();
		stack.pop_back();
		if (seen[(size_t)it.node])
			return rad_fail(L.err, RAD_ERR_INVALID,
			                "node %d '%s' is reached twice (cycle "
			                "or shared child)",
			                it.node, node_name(L, it.node));
		seen[(size_t)it.node] = 1;
		Mat4 local;
		st = node_local(L, it.node, &local);
		if (st != RAD_OK)
			return st;
		Mat4 world = mat_mul(it.parent, local);
		st = visit_node(L, it.node, world);
		const std::vector<int> &ch =
		        L.m.nodes[(size_t)it.node].children;
		for (size_t k = ch.size(); st == RAD_OK && k-- > 0;) {
			if (ch[k] < 0 || (size_t)ch[k] >= L.m.nodes.size())
				return rad_fail(L.err, RAD_ERR_INVALID,
				                "node %d '%s': child %d out "
				                "of range (%zu nodes)",
				                it.node, node_name(L, it.node),
				                ch[k], L.m.nodes.size());
			stack.push_back({ch[k], world});
		}
	}
	return st;
}

/* Parse, check, build and commit; *s is freed by the caller on error. */
rad_status load(const unsigned char *b, size_t len, rad_scene **s,
                sio_info *info, rad_error *err)
{
	tinygltf::Model m;
	rad_status st = parse(b, len, m, info, err);
	if (st == RAD_OK)
		st = check_required(m, err);
	if (st != RAD_OK)
		return st;
	count_materials(m, info);
	if (info)
		info->meshes = (uint32_t)m.meshes.size();
	st = rad_scene_new(s, err);
	if (st != RAD_OK)
		return st;
	Loader L = {m, *s, info, err, {}, {}, 0};
	L.mat_ids.assign(m.materials.size() + 1, -1);
	L.batch.reserve(9 * kBatchTriangles);
	st = walk_scene(L);
	if (st == RAD_OK)
		st = rad_scene_commit(*s, err);
	return st;
}

} // namespace

extern "C" rad_status sio_load(const void *bytes, size_t len, rad_scene **out,
                               sio_info *info, rad_error *err)
{
	rad_error_clear(err);
	if (info)
		memset(info, 0, sizeof *info);
	if (!out)
		return rad_fail(err, RAD_ERR_INVALID, "sio_load: no out");
	*out = nullptr;
	if (!bytes || len == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "empty input: no glTF bytes");
	if (len > UINT32_MAX) /* tinygltf takes 32-bit lengths */
		return rad_fail(err, RAD_ERR_UNSUPPORTED,
		                "input of %zu bytes: glTF over 4 GiB is not "
		                "supported",
		                len);
	rad_scene *s = nullptr;
	rad_status st;
	try {
		st = load(static_cast<const unsigned char *>(bytes), len, &s,
		          info, err);
	} catch (const std::bad_alloc &) {
		st = rad_fail(err, RAD_ERR_NOMEM,
		              "out of memory while importing glTF");
	} catch (const std::exception &e) {
		st = rad_fail(err, RAD_ERR_INVALID, "malformed glTF: %s",
		              e.what());
	} catch (...) {
		st = rad_fail(err, RAD_ERR_INVALID, "malformed glTF");
	}
	if (st != RAD_OK) {
		if (s)
			rad_scene_free(s);
		return st;
	}
	*out = s;
	return RAD_OK;
}

/* ------------------------------------------------------ sensor nodes */

namespace
{

rad_status find_sensors(const unsigned char *b, size_t len,
                        std::vector<sio_sensor> *out, rad_error *err)
{
	tinygltf::Model m;
	rad_status st = parse(b, len, m, nullptr, err);
	if (st == RAD_OK)
		st = check_required(m, err);
	if (st != RAD_OK)
		return st;
	Loader L = {m, nullptr, nullptr, err, {}, {}, 0, out};
	return walk_scene(L);
}

} // namespace

extern "C" rad_status sio_sensors(const void *bytes, size_t len,
                                  sio_sensor **out, size_t *n, rad_error *err)
{
	rad_error_clear(err);
	if (!out || !n)
		return rad_fail(err, RAD_ERR_INVALID, "sio_sensors: no out");
	*out = nullptr;
	*n = 0;
	if (!bytes || len == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "empty input: no glTF bytes");
	if (len > UINT32_MAX)
		return rad_fail(err, RAD_ERR_UNSUPPORTED,
		                "input of %zu bytes: glTF over 4 GiB is not "
		                "supported",
		                len);
	std::vector<sio_sensor> v;
	rad_status st;
	try {
		st = find_sensors(static_cast<const unsigned char *>(bytes),
		                  len, &v, err);
	} catch (const std::bad_alloc &) {
		st = rad_fail(err, RAD_ERR_NOMEM,
		              "out of memory while reading glTF sensors");
	} catch (const std::exception &e) {
		st = rad_fail(err, RAD_ERR_INVALID, "malformed glTF: %s",
		              e.what());
	} catch (...) {
		st = rad_fail(err, RAD_ERR_INVALID, "malformed glTF");
	}
	if (st != RAD_OK || v.empty())
		return st;
	*out = static_cast<sio_sensor *>(malloc(v.size() * sizeof v[0]));
	if (!*out)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "out of memory for %zu sensors", v.size());
	memcpy(*out, v.data(), v.size() * sizeof v[0]);
	*n = v.size();
	return RAD_OK;
}

extern "C" void sio_sensors_free(sio_sensor *s)
{
	free(s);
}

/* -------------------------------------------------------------- export */

namespace
{

/* One export: the model under construction; buffer 0 holds all data. */
struct Writer {
	tinygltf::Model m;
	std::map<std::vector<double>, int> materials; /* factors -> index */
	rad_error *err;
};

bool all_finite(const float *p, size_t n)
{
	for (size_t i = 0; i < n; i++)
		if (!std::isfinite(p[i]))
			return false;
	return true;
}

bool in_range(const double v[3], double lo, double hi)
{
	for (int c = 0; c < 3; c++)
		if (!(v[c] >= lo && v[c] <= hi))
			return false;
	return true;
}

/* Refuse what would make the output invalid glTF. */
rad_status check_mesh(const sio_mesh &g, size_t i, rad_error *err)
{
	size_t nv = g.nvertices;
	const char *bad = nullptr;
	if (nv > UINT32_MAX || g.nindices > UINT32_MAX)
		bad = "more than 2^32 - 1 vertices or indices";
	else if (!g.position)
		bad = "no positions";
	else if (g.index ? g.nindices == 0 || g.nindices % 3 != 0 : nv % 3 != 0)
		bad = "the triangle list is not a multiple of 3 long";
	else if (!all_finite(g.position, 3 * nv) ||
	         (g.color && !all_finite(g.color, 3 * nv)) ||
	         (g.illuminance && !all_finite(g.illuminance, nv)))
		bad = "a position, colour or illuminance is not finite";
	else if (!in_range(g.base_color, 0, 1) ||
	         !in_range(g.emissive, 0, HUGE_VAL) ||
	         !(g.emissive_strength >= 0 && g.emissive_strength < HUGE_VAL))
		bad = "base_color must be in [0,1], emissive and "
		      "emissive_strength finite and >= 0";
	if (bad)
		return rad_fail(err, RAD_ERR_INVALID, "mesh %zu '%s': %s", i,
		                g.name ? g.name : "", bad);
	for (size_t k = 0; g.index && k < g.nindices; k++)
		if (g.index[k] >= nv)
			return rad_fail(err, RAD_ERR_INVALID,
			                "mesh %zu '%s': index %u (at position "
			                "%zu) >= vertex count %zu",
			                i, g.name ? g.name : "", g.index[k], k,
			                nv);
	return RAD_OK;
}

/* Append n bytes as a new bufferView, keeping every view 4-aligned. */
int add_view(tinygltf::Model &m, const void *p, size_t n, int target)
{
	std::vector<unsigned char> &data = m.buffers[0].data;
	tinygltf::BufferView bv;
	bv.buffer = 0;
	bv.byteOffset = data.size(); /* a multiple of 4, see below */
	bv.byteLength = n;
	bv.target = target;
	const unsigned char *b = static_cast<const unsigned char *>(p);
	data.insert(data.end(), b, b + n);
	data.resize((data.size() + 3) & ~(size_t)3, 0);
	m.bufferViews.push_back(bv);
	return (int)m.bufferViews.size() - 1;
}

/* A tightly packed accessor of 4-byte components over its own view. */
int add_accessor(tinygltf::Model &m, const void *p, size_t count, int type,
                 int ncomp, int comp, int target)
{
	tinygltf::Accessor a;
	a.bufferView = add_view(m, p, 4 * (size_t)ncomp * count, target);
	a.componentType = comp;
	a.type = type;
	a.count = count;
	m.accessors.push_back(a);
	return (int)m.accessors.size() - 1;
}

void add_node(tinygltf::Model &m, tinygltf::Node &&n)
{
	m.nodes.push_back(std::move(n));
	m.scenes[0].nodes.push_back((int)m.nodes.size() - 1);
}

/*
 * Material of a mesh, shared between meshes with equal factors.  An
 * emissive factor above 1 (not allowed by glTF) is folded into
 * emissive_strength, which keeps the luminance.
 */
int write_material(Writer &W, const sio_mesh &g)
{
	double e[3], strength = g.emissive_strength;
	double emax =
	        std::max(g.emissive[0], std::max(g.emissive[1], g.emissive[2]));
	double scale = emax > 1 ? emax : 1;
	for (int c = 0; c < 3; c++)
		e[c] = g.emissive[c] / scale;
	strength = emax > 0 ? strength * scale : 1;
	std::vector<double> key = {g.base_color[0],
	                           g.base_color[1],
	                           g.base_color[2],
	                           e[0],
	                           e[1],
	                           e[2],
	                           strength};
	auto it = W.materials.find(key);
	if (it != W.materials.end())
		return it->second;
	tinygltf::Material mat;
	mat.pbrMetallicRoughness.baseColorFactor = {
	        g.base_color[0], g.base_color[1], g.base_color[2], 1};
	mat.pbrMetallicRoughness.metallicFactor = 0; /* we are diffuse */
	mat.emissiveFactor = {e[0], e[1], e[2]};
	if (strength != 1) {
		tinygltf::Value::Object ext;
		ext["emissiveStrength"] = tinygltf::Value(strength);
		mat.extensions[kStrengthExt] = tinygltf::Value(std::move(ext));
	}
	W.m.materials.push_back(std::move(mat));
	int idx = (int)W.m.materials.size() - 1;
	W.materials[key] = idx;
	return idx;
}

rad_status write_mesh(Writer &W, const sio_mesh &g, size_t i)
{
	if (g.nvertices == 0 && g.nindices == 0)
		return RAD_OK; /* nothing to draw; glTF forbids empty data */
	rad_status st = check_mesh(g, i, W.err);
	if (st != RAD_OK)
		return st;
	size_t nv = g.nvertices;
	tinygltf::Primitive p;
	p.mode = TINYGLTF_MODE_TRIANGLES;
	int pa = add_accessor(W.m, g.position, nv, TINYGLTF_TYPE_VEC3, 3,
	                      TINYGLTF_COMPONENT_TYPE_FLOAT,
	                      TINYGLTF_TARGET_ARRAY_BUFFER);
	/* POSITION min/max are required; tinygltf leaves them to us. */
	std::vector<double> lo(3, HUGE_VAL), hi(3, -HUGE_VAL);
	for (size_t k = 0; k < 3 * nv; k++) {
		lo[k % 3] = std::min(lo[k % 3], (double)g.position[k]);
		hi[k % 3] = std::max(hi[k % 3], (double)g.position[k]);
	}
	W.m.accessors[(size_t)pa].minValues = lo;
	W.m.accessors[(size_t)pa].maxValues = hi;
	p.attributes["POSITION"] = pa;
	if (g.color)
		p.attributes["COLOR_0"] =
		        add_accessor(W.m, g.color, nv, TINYGLTF_TYPE_VEC3, 3,
		                     TINYGLTF_COMPONENT_TYPE_FLOAT,
		                     TINYGLTF_TARGET_ARRAY_BUFFER);
	if (g.illuminance)
		p.attributes["_ILLUMINANCE"] = add_accessor(
		        W.m, g.illuminance, nv, TINYGLTF_TYPE_SCALAR, 1,
		        TINYGLTF_COMPONENT_TYPE_FLOAT,
		        TINYGLTF_TARGET_ARRAY_BUFFER);
	if (g.index)
		p.indices = add_accessor(W.m, g.index, g.nindices,
		                         TINYGLTF_TYPE_SCALAR, 1,
		                         TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
		                         TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
	p.material = write_material(W, g);
	tinygltf::Mesh mesh;
	mesh.name = g.name ? g.name : "";
	mesh.primitives.push_back(std::move(p));
	W.m.meshes.push_back(std::move(mesh));
	tinygltf::Node node;
	node.name = g.name ? g.name : "";
	node.mesh = (int)W.m.meshes.size() - 1;
	add_node(W.m, std::move(node));
	return RAD_OK;
}

rad_status check_light(const rad_light_desc &d, size_t i, rad_error *err)
{
	bool aimed = d.kind != RAD_LIGHT_POINT;
	double dlen2 = d.direction[0] * d.direction[0] +
	               d.direction[1] * d.direction[1] +
	               d.direction[2] * d.direction[2];
	bool ok = (d.kind == RAD_LIGHT_POINT || d.kind == RAD_LIGHT_SPOT ||
	           d.kind == RAD_LIGHT_DIRECTIONAL) &&
	          in_range(d.position, -HUGE_VAL, HUGE_VAL) &&
	          in_range(d.intensity, 0, HUGE_VAL) &&
	          (!aimed || (dlen2 > 0 && dlen2 < HUGE_VAL)) && d.range >= 0 &&
	          d.range < HUGE_VAL &&
	          (d.kind != RAD_LIGHT_SPOT ||
	           (d.inner_cone >= 0 && d.inner_cone < d.outer_cone &&
	            d.outer_cone <= M_PI / 2));
	if (!ok)
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %zu '%s': needs a known kind, finite "
		                "position, intensity >= 0, range >= 0, a "
		                "non-zero direction (spot, directional) and "
		                "0 <= inner < outer <= pi/2 (spot)",
		                i, d.name ? d.name : "");
	return RAD_OK;
}

/* Unit quaternion (x y z w) turning the local -Z axis onto direction d. */
std::vector<double> aim(const double d[3])
{
	double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
	double x = d[0] / len, y = d[1] / len, z = d[2] / len;
	/* Half-way quaternion (a x b, 1 + a.b) with a = -Z; when b = +Z the
	 * axis is undefined and any half turn about X or Y will do. */
	if (1 - z < 1e-12)
		return {1, 0, 0, 0};
	double n = std::sqrt(y * y + x * x + (1 - z) * (1 - z));
	return {y / n, -x / n, 0, (1 - z) / n};
}

rad_status write_light(Writer &W, const rad_light_desc &d, size_t i)
{
	rad_status st = check_light(d, i, W.err);
	if (st != RAD_OK)
		return st;
	tinygltf::Light g;
	g.type = d.kind == RAD_LIGHT_POINT  ? "point"
	         : d.kind == RAD_LIGHT_SPOT ? "spot"
	                                    : "directional";
	/* glTF splits intensity into a colour in [0,1] and a scalar. */
	double imax = std::max(d.intensity[0],
	                       std::max(d.intensity[1], d.intensity[2]));
	g.intensity = imax;
	for (int c = 0; c < 3; c++)
		g.color.push_back(imax > 0 ? d.intensity[c] / imax : 1);
	g.range = d.range;
	g.spot.innerConeAngle = d.inner_cone;
	g.spot.outerConeAngle = d.outer_cone;
	g.name = d.name ? d.name : "";
	W.m.lights.push_back(g);
	tinygltf::Node n;
	n.name = g.name;
	if (d.position[0] != 0 || d.position[1] != 0 || d.position[2] != 0)
		n.translation.assign(d.position, d.position + 3);
	if (d.kind != RAD_LIGHT_POINT)
		n.rotation = aim(d.direction);
	tinygltf::Value::Object ext;
	ext["light"] = tinygltf::Value((int)W.m.lights.size() - 1);
	n.extensions[kLightsExt] = tinygltf::Value(std::move(ext));
	add_node(W.m, std::move(n));
	return RAD_OK;
}

rad_status write(const sio_mesh *meshes, size_t nmeshes,
                 const rad_light_desc *lights, size_t nlights, sio_format fmt,
                 std::string *bytes, rad_error *err)
{
	Writer W;
	W.err = err;
	W.m.asset.version = "2.0";
	W.m.asset.generator = "luxrad";
	W.m.buffers.resize(1);
	W.m.scenes.resize(1);
	W.m.defaultScene = 0;
	rad_status st = RAD_OK;
	for (size_t i = 0; st == RAD_OK && i < nmeshes; i++)
		st = write_mesh(W, meshes[i], i);
	for (size_t i = 0; st == RAD_OK && i < nlights; i++)
		st = write_light(W, lights[i], i);
	if (st != RAD_OK)
		return st;
	if (W.m.nodes.empty()) { /* tinygltf writes an empty scene as null */
		W.m.scenes.clear();
		W.m.defaultScene = -1;
	}
	if (W.m.buffers[0].data.empty())
		W.m.buffers.clear(); /* glTF forbids empty buffers */
	else if (W.m.buffers[0].data.size() > UINT32_MAX / 2)
		return rad_fail(err, RAD_ERR_LIMIT,
		                "%zu bytes of vertex data: glTF output is "
		                "limited to 2 GiB",
		                W.m.buffers[0].data.size());
	for (const tinygltf::Material &mat : W.m.materials)
		if (mat.extensions.count(kStrengthExt)) {
			W.m.extensionsUsed.push_back(kStrengthExt);
			break;
		}
	if (nlights)
		W.m.extensionsUsed.push_back(kLightsExt);
	std::stringstream ss;
	tinygltf::TinyGLTF writer;
	if (!writer.WriteGltfSceneToStream(&W.m, ss, fmt == SIO_FORMAT_JSON,
	                                   fmt == SIO_FORMAT_GLB))
		return rad_fail(err, RAD_ERR_INVALID,
		                "tinygltf could not serialize the model");
	*bytes = ss.str();
	return RAD_OK;
}

} // namespace

extern "C" rad_status sio_write(const sio_mesh *meshes, size_t nmeshes,
                                const rad_light_desc *lights, size_t nlights,
                                sio_format fmt, void **out, size_t *outlen,
                                rad_error *err)
{
	rad_error_clear(err);
	if (!out || !outlen || (nmeshes && !meshes) || (nlights && !lights) ||
	    (fmt != SIO_FORMAT_GLB && fmt != SIO_FORMAT_JSON))
		return rad_fail(err, RAD_ERR_INVALID,
		                "sio_write: bad arguments");
	*out = nullptr;
	*outlen = 0;
	std::string bytes;
	rad_status st;
	try {
		st = write(meshes, nmeshes, lights, nlights, fmt, &bytes, err);
	} catch (const std::bad_alloc &) {
		st = rad_fail(err, RAD_ERR_NOMEM,
		              "out of memory while exporting glTF");
	} catch (const std::exception &e) {
		st = rad_fail(err, RAD_ERR_INVALID, "glTF export failed: %s",
		              e.what());
	}
	if (st != RAD_OK)
		return st;
	void *p = malloc(bytes.size());
	if (!p)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "out of memory for %zu bytes of glTF",
		                bytes.size());
	memcpy(p, bytes.data(), bytes.size());
	*out = p;
	*outlen = bytes.size();
	return RAD_OK;
}
