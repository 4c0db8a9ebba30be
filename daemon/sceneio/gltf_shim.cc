/*
 * gltf_shim.cc -- the one C++ file of luxrad and the only one that sees
 * tinygltf: it parses bytes into tinygltf's model and hands the model out
 * as plain C data (gltf_doc.h), and it serializes a document the C writer
 * built.  Everything else -- checking indices and byte ranges, walking
 * nodes, building the engine scene, reading sensors, choosing what to
 * write -- is C, in the other files of this folder.
 *
 * DESIGN
 *  - No exception crosses the C boundary: every entry point catches;
 *    std::bad_alloc becomes RAD_ERR_NOMEM.
 *  - tinygltf comes from the Debian shared library: no TINYGLTF_* defines
 *    here (they would break the ODR, see docs/PITFALLS.md).  Its filesystem
 *    callbacks are replaced by ones that refuse every path and its image
 *    loader by one that keeps the encoded bytes, so a document can
 *    neither make us read a file nor have tinygltf decode an image.
 *  - The bytes tinygltf would mishandle (a GLB chunk running past the
 *    data, JSON nested deep enough to overflow its recursion) never reach
 *    it: precheck.c refuses them first.
 *  - The C view points into the model, so the model stays allocated, and
 *    unmodified, until sio_doc_free().  The view and the model's own
 *    struct live in pages of their own, off the heap, and extension
 *    members are looked up on demand (sio_doc_node_light...) with
 *    tinygltf's lookups: the import's heap traffic stays what the engine's
 *    memory figures were measured with (load.c).
 *  - tinygltf's Value::Get asserts that the value is an object: Has()
 *    (which checks) always comes first.
 */
#include <tiny_gltf.h>

#include <sys/mman.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include "gltf_doc.h"
#include "internal.h"

extern "C" {
#include "rad.h"
}

/* gltf_doc.h's codes are tinygltf's. */
#define SAME_(name, tiny) static_assert(SIO_GL_##name == TINYGLTF_##tiny, #name)
SAME_(TRIANGLES, MODE_TRIANGLES);
SAME_(TRIANGLE_STRIP, MODE_TRIANGLE_STRIP);
SAME_(TRIANGLE_FAN, MODE_TRIANGLE_FAN);
SAME_(UNSIGNED_BYTE, COMPONENT_TYPE_UNSIGNED_BYTE);
SAME_(UNSIGNED_SHORT, COMPONENT_TYPE_UNSIGNED_SHORT);
SAME_(UNSIGNED_INT, COMPONENT_TYPE_UNSIGNED_INT);
SAME_(FLOAT, COMPONENT_TYPE_FLOAT);
SAME_(ARRAY_BUFFER, TARGET_ARRAY_BUFFER);
SAME_(ELEMENT_ARRAY_BUFFER, TARGET_ELEMENT_ARRAY_BUFFER);
SAME_(VEC2, TYPE_VEC2);
SAME_(VEC3, TYPE_VEC3);
SAME_(VEC4, TYPE_VEC4);
SAME_(SCALAR, TYPE_SCALAR);
#undef SAME_

/* The model and the C view of it, both outside the malloc heap (see
 * map_pages). */
struct sio_doc_owner {
	tinygltf::Model m;
	void *arrays;      /* one mapping holding every array of doc */
	size_t arrays_len; /* bytes mapped, 0: none */
	sio_doc doc;
};

namespace
{

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

sio_str str(const std::string &s)
{
	return sio_str{s.c_str(), s.size()};
}

/*
 * Pages for the owner and the C view.  The engine's memory figures count
 * malloc_usable_size, which depends on the heap's history; kept off the
 * heap, the view leaves the heap as tinygltf and the engine alone leave
 * it, so the figures stay reproducible from one version to the next.
 */
void *map_pages(size_t len)
{
	void *p = mmap(nullptr, len, PROT_READ | PROT_WRITE,
	               MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
	if (p == MAP_FAILED)
		throw std::bad_alloc();
	return p;
}

size_t span(size_t bytes)
{
	return (bytes + 15) & ~(size_t)15;
}

/* The next n elements of type T from the mapping at *p. */
template <typename T> T *carve(unsigned char **p, size_t n)
{
	T *r = reinterpret_cast<T *>(*p);
	*p += span(n * sizeof(T));
	return r;
}

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

/*
 * Images are not decoded here (texture.c decodes those a base colour
 * needs, when it needs them).  A bufferView's bytes stay where they are;
 * a data: URI's, decoded by tinygltf into a temporary, are kept in the
 * image as they came, still encoded.
 */
bool keep_image(tinygltf::Image *img, const int, std::string *, std::string *,
                int, int, const unsigned char *bytes, int size, void *)
{
	if (img->bufferView < 0 && bytes && size > 0)
		img->image.assign(bytes, bytes + size);
	return true;
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
		return rad_fail(
		        err, RAD_ERR_INVALID,
		        "buffer %zu: external URI '%.80s%s' refused: a "
		        "scene sent as bytes carries its buffers (data: "
		        "URIs or a GLB); luxrad submit and the tools "
		        "pack a .gltf with the files beside it",
		        buf, r.path.c_str(), r.path.size() > 80 ? "..." : "");
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
		                SIO_LIGHTS_EXT, m.lights.size());
	return rad_fail(err, RAD_ERR_INVALID, "malformed glTF: %s",
	                one_line(msg).c_str());
}

/*
 * tinygltf's warnings into the report.  An image with an external file is
 * looked for (and refused) by the filesystem callbacks: tinygltf then
 * writes "File not found : NAME" and "Failed to load external 'uri' for
 * image[i]", which read as if we had looked for the user's files.  Those
 * become one note saying what happened; other lines pass as they are.
 */
void note_warnings(const std::string &warn, sio_info *info)
{
	std::string rest;
	size_t images = 0, at = 0;
	while (at < warn.size()) {
		size_t end = warn.find('\n', at);
		if (end == std::string::npos)
			end = warn.size();
		std::string line = warn.substr(at, end - at);
		at = end + 1;
		if (line.rfind("Failed to load external 'uri' for image", 0) ==
		    0)
			images++;
		else if (line.rfind("File not found : ", 0) != 0 &&
		         !line.empty())
			rest += (rest.empty() ? "" : " ") + line;
	}
	if (images)
		sio_note(
		        info,
		        "%zu image%s with an external file not read: a scene "
		        "sent as bytes carries its images (luxrad submit packs "
		        "a .gltf with the files beside it)",
		        images, images == 1 ? "" : "s");
	if (!rest.empty())
		sio_note(info, "%s", one_line(rest).c_str());
}

rad_status parse(const unsigned char *b, size_t len, bool glb,
                 tinygltf::Model &m, sio_info *info, rad_error *err)
{
	Refusal refusal;
	tinygltf::TinyGLTF loader;
	loader.SetFsCallbacks(tinygltf::FsCallbacks{
	        fs_exists, fs_expand, fs_read, fs_write, &refusal});
	loader.SetImageLoader(keep_image, nullptr);
	std::string terr, twarn;
	bool ok = glb ? loader.LoadBinaryFromMemory(&m, &terr, &twarn, b,
	                                            (unsigned)len, "")
	              : loader.LoadASCIIFromString(
	                        &m, &terr, &twarn,
	                        reinterpret_cast<const char *>(b),
	                        (unsigned)len, "");
	note_warnings(twarn, info);
	if (!ok)
		return parse_failed(terr, refusal, m, err);
	return RAD_OK;
}

/* --------------------------------------------------------- the C view */

sio_doc_node view_node(const tinygltf::Node &n)
{
	sio_doc_node c = {};
	c.name = str(n.name);
	c.matrix = n.matrix.data();
	c.nmatrix = n.matrix.size();
	c.translation = n.translation.data();
	c.ntranslation = n.translation.size();
	c.rotation = n.rotation.data();
	c.nrotation = n.rotation.size();
	c.scale = n.scale.data();
	c.nscale = n.scale.size();
	c.children = n.children.data();
	c.nchildren = n.children.size();
	c.mesh = n.mesh;
	return c;
}

/* Member key of object v as n numbers into out; false if present but not
 * that. */
bool numbers(const tinygltf::Value &v, const char *key, double *out, size_t n)
{
	if (!v.Has(key))
		return true;
	const tinygltf::Value &m = v.Get(key);
	if (n == 1) {
		if (!m.IsNumber())
			return false;
		out[0] = m.GetNumberAsDouble();
		return true;
	}
	if (!m.IsArray() || m.ArrayLen() != n)
		return false;
	for (size_t k = 0; k < n; k++) {
		if (!m.Get((int)k).IsNumber())
			return false;
		out[k] = m.Get((int)k).GetNumberAsDouble();
	}
	return true;
}

/* The base colour texture and its KHR_texture_transform. */
void view_base_texture(const tinygltf::TextureInfo &t, sio_doc_material &c)
{
	c.base_texture = t.index;
	c.base_texcoord = t.texCoord;
	c.scale[0] = c.scale[1] = 1;
	c.transform_texcoord = -1;
	auto ext = t.extensions.find(SIO_TRANSFORM_EXT);
	if (ext == t.extensions.end())
		return;
	const tinygltf::Value &v = ext->second;
	c.has_transform = 1;
	if (!v.IsObject()) {
		c.transform_bad = 1;
		return;
	}
	double tc = -1;
	bool ok = numbers(v, "offset", c.offset, 2) &&
	          numbers(v, "rotation", &c.rotation, 1) &&
	          numbers(v, "scale", c.scale, 2) &&
	          numbers(v, "texCoord", &tc, 1);
	if (!ok || !(tc >= -1 && tc <= 1e6) || tc != (int)tc)
		c.transform_bad = 1;
	else
		c.transform_texcoord = (int)tc;
}

sio_doc_material view_material(const tinygltf::Material &mat)
{
	const tinygltf::PbrMetallicRoughness &pbr = mat.pbrMetallicRoughness;
	sio_doc_material c = {};
	c.name = str(mat.name);
	/* tinygltf guarantees 4 and 3 numbers (defaults when absent). */
	for (size_t k = 0; k < 3; k++) {
		c.base_color[k] = pbr.baseColorFactor[k];
		c.emissive[k] = mat.emissiveFactor[k];
	}
	c.metallic = pbr.metallicFactor;
	c.double_sided = mat.doubleSided;
	c.textures = (pbr.baseColorTexture.index >= 0) +
	             (pbr.metallicRoughnessTexture.index >= 0) +
	             (mat.normalTexture.index >= 0) +
	             (mat.occlusionTexture.index >= 0) +
	             (mat.emissiveTexture.index >= 0);
	view_base_texture(pbr.baseColorTexture, c);
	return c;
}

/* The C view of v, made element by element by f, carved from *p. */
template <typename T, typename V, typename F>
const T *mirror(unsigned char **p, const std::vector<V> &v, size_t *n, F f)
{
	T *out = carve<T>(p, v.size());
	for (size_t i = 0; i < v.size(); i++)
		out[i] = f(v[i]);
	*n = v.size();
	return out;
}

/* Meshes and their primitives, the primitives in one array. */
void view_meshes(const tinygltf::Model &m, unsigned char **p, sio_doc &d,
                 size_t nprims)
{
	sio_doc_prim *prim = carve<sio_doc_prim>(p, nprims);
	d.meshes = mirror<sio_doc_mesh>(
	        p, m.meshes, &d.nmeshes, [&](const tinygltf::Mesh &mesh) {
		        sio_doc_mesh c = {str(mesh.name), prim,
		                          mesh.primitives.size()};
		        for (const tinygltf::Primitive &gp : mesh.primitives) {
			        auto pos = gp.attributes.find("POSITION");
			        bool has = pos != gp.attributes.end();
			        sio_doc_prim cp = {gp.mode,
			                           has,
			                           has ? pos->second : -1,
			                           gp.indices,
			                           gp.material,
			                           {}};
			        for (int k = 0; k < SIO_TEXCOORDS; k++) {
				        auto uv = gp.attributes.find(
				                "TEXCOORD_" +
				                std::to_string(k));
				        cp.texcoord[k] =
				                uv != gp.attributes.end()
				                        ? uv->second
				                        : -1;
			        }
			        *prim++ = cp;
		        }
		        return c;
	        });
}

void view(sio_doc_owner &o)
{
	const tinygltf::Model &m = o.m;
	sio_doc &d = o.doc;
	size_t nprims = 0;
	for (const tinygltf::Mesh &mesh : m.meshes)
		nprims += mesh.primitives.size();
	size_t len = span(m.nodes.size() * sizeof(sio_doc_node)) +
	             span(m.meshes.size() * sizeof(sio_doc_mesh)) +
	             span(nprims * sizeof(sio_doc_prim)) +
	             span(m.accessors.size() * sizeof(sio_doc_accessor)) +
	             span(m.bufferViews.size() * sizeof(sio_doc_view)) +
	             span(m.buffers.size() * sizeof(sio_doc_buffer)) +
	             span(m.materials.size() * sizeof(sio_doc_material)) +
	             span(m.textures.size() * sizeof(sio_doc_texture)) +
	             span(m.samplers.size() * sizeof(sio_doc_sampler)) +
	             span(m.images.size() * sizeof(sio_doc_image)) +
	             span(m.lights.size() * sizeof(sio_doc_light)) +
	             span(m.scenes.size() * sizeof(sio_doc_scene)) +
	             span(m.extensionsRequired.size() * sizeof(sio_str)) +
	             span(m.extensionsUsed.size() * sizeof(sio_str));
	if (len) {
		o.arrays = map_pages(len);
		o.arrays_len = len;
	}
	unsigned char *p = static_cast<unsigned char *>(o.arrays);
	d.nodes = mirror<sio_doc_node>(&p, m.nodes, &d.nnodes, view_node);
	view_meshes(m, &p, d, nprims);
	d.accessors = mirror<sio_doc_accessor>(
	        &p, m.accessors, &d.naccessors,
	        [](const tinygltf::Accessor &x) {
		        return sio_doc_accessor{x.sparse.isSparse, x.bufferView,
		                                x.componentType,   x.type,
		                                x.normalized,      x.count,
		                                x.byteOffset};
	        });
	d.views = mirror<sio_doc_view>(
	        &p, m.bufferViews, &d.nviews,
	        [](const tinygltf::BufferView &v) {
		        return sio_doc_view{v.buffer, v.byteOffset,
		                            v.byteLength, v.byteStride};
	        });
	d.buffers = mirror<sio_doc_buffer>(
	        &p, m.buffers, &d.nbuffers, [](const tinygltf::Buffer &b) {
		        return sio_doc_buffer{b.data.data(), b.data.size()};
	        });
	d.materials = mirror<sio_doc_material>(&p, m.materials, &d.nmaterials,
	                                       view_material);
	d.textures = mirror<sio_doc_texture>(
	        &p, m.textures, &d.ntextures, [](const tinygltf::Texture &t) {
		        return sio_doc_texture{t.source, t.sampler};
	        });
	d.samplers = mirror<sio_doc_sampler>(
	        &p, m.samplers, &d.nsamplers, [](const tinygltf::Sampler &x) {
		        return sio_doc_sampler{x.wrapS, x.wrapT};
	        });
	d.images = mirror<sio_doc_image>(
	        &p, m.images, &d.nimages, [](const tinygltf::Image &x) {
		        bool data = x.bufferView < 0 && !x.image.empty();
		        return sio_doc_image{
		                str(x.name),
		                str(x.mimeType),
		                x.bufferView,
		                data ? x.image.data() : nullptr,
		                data ? x.image.size() : 0,
		                x.bufferView < 0 && !data && !x.uri.empty() &&
		                        x.uri.rfind("data:", 0) != 0};
	        });
	d.lights = mirror<sio_doc_light>(
	        &p, m.lights, &d.nlights, [](const tinygltf::Light &l) {
		        return sio_doc_light{
		                str(l.name),           str(l.type),
		                l.color.data(),        l.color.size(),
		                l.intensity,           l.range,
		                l.spot.innerConeAngle, l.spot.outerConeAngle};
	        });
	d.scenes = mirror<sio_doc_scene>(
	        &p, m.scenes, &d.nscenes, [](const tinygltf::Scene &sc) {
		        return sio_doc_scene{sc.nodes.data(), sc.nodes.size()};
	        });
	d.required =
	        mirror<sio_str>(&p, m.extensionsRequired, &d.nrequired, str);
	d.used = mirror<sio_str>(&p, m.extensionsUsed, &d.nused, str);
	d.default_scene = m.defaultScene;
	d.own = &o;
}

/* ------------------------------------------------------------ writing */

void write_mesh(tinygltf::Model &m, const sio_out_mesh &g)
{
	tinygltf::Primitive p;
	p.mode = TINYGLTF_MODE_TRIANGLES;
	for (int k = 0; k < g.nattrs; k++)
		p.attributes[g.attrs[k].name] = g.attrs[k].accessor;
	p.indices = g.indices;
	p.material = g.material;
	tinygltf::Mesh mesh;
	mesh.name = g.name;
	mesh.primitives.push_back(std::move(p));
	m.meshes.push_back(std::move(mesh));
}

void write_material(tinygltf::Model &m, const sio_out_material &g)
{
	tinygltf::Material mat;
	mat.pbrMetallicRoughness.baseColorFactor = {
	        g.base_color[0], g.base_color[1], g.base_color[2], 1};
	mat.pbrMetallicRoughness.metallicFactor = 0;
	mat.emissiveFactor = {g.emissive[0], g.emissive[1], g.emissive[2]};
	if (g.strength_ext) {
		tinygltf::Value::Object ext;
		ext["emissiveStrength"] = tinygltf::Value(g.strength);
		mat.extensions[SIO_STRENGTH_EXT] =
		        tinygltf::Value(std::move(ext));
	}
	m.materials.push_back(std::move(mat));
}

void write_light(tinygltf::Model &m, const sio_out_light &g)
{
	tinygltf::Light l;
	l.type = g.type;
	l.intensity = g.intensity;
	l.color.assign(g.color, g.color + 3);
	l.range = g.range;
	l.spot.innerConeAngle = g.inner_cone;
	l.spot.outerConeAngle = g.outer_cone;
	l.name = g.name;
	m.lights.push_back(std::move(l));
}

void write_node(tinygltf::Model &m, const sio_out_node &g)
{
	tinygltf::Node n;
	n.name = g.name;
	n.mesh = g.mesh;
	if (g.translated)
		n.translation.assign(g.translation, g.translation + 3);
	if (g.rotated)
		n.rotation.assign(g.rotation, g.rotation + 4);
	if (g.light >= 0) {
		tinygltf::Value::Object ext;
		ext["light"] = tinygltf::Value(g.light);
		n.extensions[SIO_LIGHTS_EXT] = tinygltf::Value(std::move(ext));
	}
	m.nodes.push_back(std::move(n));
}

rad_status write(const sio_out &o, sio_format fmt, std::string *bytes,
                 rad_error *err)
{
	tinygltf::Model m;
	m.asset.version = "2.0";
	m.asset.generator = o.generator;
	if (o.size) { /* glTF forbids empty buffers */
		m.buffers.resize(1);
		m.buffers[0].data.assign(o.data, o.data + o.size);
	}
	for (size_t i = 0; i < o.nviews; i++) {
		tinygltf::BufferView bv;
		bv.buffer = 0;
		bv.byteOffset = o.views[i].offset;
		bv.byteLength = o.views[i].length;
		bv.target = o.views[i].target;
		m.bufferViews.push_back(bv);
	}
	for (size_t i = 0; i < o.naccessors; i++) {
		const sio_out_accessor &g = o.accessors[i];
		tinygltf::Accessor a;
		a.bufferView = g.view;
		a.componentType = g.component_type;
		a.type = g.type;
		a.count = g.count;
		if (g.bounded) {
			a.minValues.assign(g.min, g.min + 3);
			a.maxValues.assign(g.max, g.max + 3);
		}
		m.accessors.push_back(a);
	}
	for (size_t i = 0; i < o.nmeshes; i++)
		write_mesh(m, o.meshes[i]);
	for (size_t i = 0; i < o.nmaterials; i++)
		write_material(m, o.materials[i]);
	for (size_t i = 0; i < o.nlights; i++)
		write_light(m, o.lights[i]);
	for (size_t i = 0; i < o.nnodes; i++)
		write_node(m, o.nodes[i]);
	if (o.nnodes) { /* tinygltf writes an empty scene as null */
		m.scenes.resize(1);
		for (size_t i = 0; i < o.nnodes; i++)
			m.scenes[0].nodes.push_back((int)i);
		m.defaultScene = 0;
	}
	for (size_t i = 0; i < o.nextensions_used; i++)
		m.extensionsUsed.push_back(o.extensions_used[i]);
	std::stringstream ss;
	tinygltf::TinyGLTF writer;
	if (!writer.WriteGltfSceneToStream(&m, ss, fmt == SIO_FORMAT_JSON,
	                                   fmt == SIO_FORMAT_GLB))
		return rad_fail(err, RAD_ERR_INVALID,
		                "tinygltf could not serialize the model");
	*bytes = ss.str();
	return RAD_OK;
}

} // namespace

enum Job { IMPORT, EXPORT };

/* Run f, which returns a rad_status; exceptions become errors. */
template <typename F> rad_status guarded(rad_error *err, Job job, F f)
{
	const char *doing = job == IMPORT ? "importing" : "exporting";
	const char *failed =
	        job == IMPORT ? "malformed glTF" : "glTF export failed";
	try {
		return f();
	} catch (const std::bad_alloc &) {
		return rad_fail(err, RAD_ERR_NOMEM,
		                "out of memory while %s glTF", doing);
	} catch (const std::exception &e) {
		return rad_fail(err, RAD_ERR_INVALID, "%s: %s", failed,
		                e.what());
	} catch (...) {
		return rad_fail(err, RAD_ERR_INVALID, "%s", failed);
	}
}

/* Undo sio_doc_parse: the model's own memory goes back to the heap. */
static void release(sio_doc_owner *o)
{
	if (o->arrays_len)
		munmap(o->arrays, o->arrays_len);
	o->~sio_doc_owner();
	munmap(o, sizeof *o);
}

extern "C" rad_status sio_doc_parse(const unsigned char *bytes, size_t len,
                                    int glb, sio_doc **out, sio_info *info,
                                    rad_error *err)
{
	*out = nullptr;
	sio_doc_owner *o = nullptr;
	rad_status st = guarded(err, IMPORT, [&] {
		o = new (map_pages(sizeof *o)) sio_doc_owner();
		rad_status r = parse(bytes, len, glb, o->m, info, err);
		if (r == RAD_OK)
			view(*o);
		return r;
	});
	if (st != RAD_OK) {
		if (o)
			release(o);
		return st;
	}
	*out = &o->doc;
	return RAD_OK;
}

extern "C" void sio_doc_free(sio_doc *d)
{
	if (d)
		release(d->own);
}

extern "C" rad_status sio_doc_node_light(const sio_doc *d, int ni, sio_val *tag,
                                         double *light, rad_error *err)
{
	const tinygltf::Node &n = d->own->m.nodes[(size_t)ni];
	*tag = SIO_VAL_ABSENT;
	return guarded(err, IMPORT, [&] {
		auto it = n.extensions.find(SIO_LIGHTS_EXT);
		if (it == n.extensions.end())
			return RAD_OK;
		const tinygltf::Value &v = it->second;
		*tag = SIO_VAL_OTHER;
		if (v.Has("light") && v.Get("light").IsNumber()) {
			*tag = SIO_VAL_NUMBER;
			*light = v.Get("light").GetNumberAsDouble();
		}
		return RAD_OK;
	});
}

extern "C" rad_status sio_doc_node_sensor(const sio_doc *d, int ni,
                                          sio_val *tag, sio_str *name,
                                          rad_error *err)
{
	const tinygltf::Node &n = d->own->m.nodes[(size_t)ni];
	*tag = SIO_VAL_ABSENT;
	return guarded(err, IMPORT, [&] {
		if (!n.extras.IsObject() || !n.extras.Has(SIO_SENSOR_EXTRA))
			return RAD_OK;
		const tinygltf::Value &v = n.extras.Get(SIO_SENSOR_EXTRA);
		*tag = v.IsString() ? SIO_VAL_STRING : SIO_VAL_OTHER;
		if (v.IsString())
			*name = str(v.Get<std::string>());
		return RAD_OK;
	});
}

extern "C" rad_status sio_doc_node_photometry(const sio_doc *d, int ni,
                                              sio_val *tag, double *view,
                                              sio_str *name, rad_error *err)
{
	const tinygltf::Node &n = d->own->m.nodes[(size_t)ni];
	*tag = SIO_VAL_ABSENT;
	return guarded(err, IMPORT, [&] {
		if (!n.extras.IsObject() || !n.extras.Has(SIO_PHOTOMETRY_EXTRA))
			return RAD_OK;
		const tinygltf::Value &v = n.extras.Get(SIO_PHOTOMETRY_EXTRA);
		*tag = SIO_VAL_OTHER;
		if (v.IsString()) {
			*tag = SIO_VAL_STRING;
			*name = str(v.Get<std::string>());
		} else if (v.IsObject() && v.Has("bufferView") &&
		           v.Get("bufferView").IsNumber()) {
			*tag = SIO_VAL_NUMBER;
			*view = v.Get("bufferView").GetNumberAsDouble();
			if (v.Has("name") && v.Get("name").IsString())
				*name = str(v.Get("name").Get<std::string>());
		}
		return RAD_OK;
	});
}

extern "C" rad_status sio_doc_material_strength(const sio_doc *d, int mi,
                                                sio_val *tag, double *strength,
                                                rad_error *err)
{
	const tinygltf::Material &mat = d->own->m.materials[(size_t)mi];
	*tag = SIO_VAL_ABSENT;
	return guarded(err, IMPORT, [&] {
		auto it = mat.extensions.find(SIO_STRENGTH_EXT);
		if (it == mat.extensions.end() ||
		    !it->second.Has("emissiveStrength"))
			return RAD_OK;
		const tinygltf::Value &v = it->second.Get("emissiveStrength");
		*tag = v.IsNumber() ? SIO_VAL_NUMBER : SIO_VAL_OTHER;
		if (v.IsNumber())
			*strength = v.GetNumberAsDouble();
		return RAD_OK;
	});
}

extern "C" rad_status sio_doc_write(const sio_out *o, sio_format fmt,
                                    void **out, size_t *outlen, rad_error *err)
{
	std::string bytes;
	rad_status st = guarded(err, EXPORT,
	                        [&] { return write(*o, fmt, &bytes, err); });
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
