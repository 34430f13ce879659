// OSMesa offscreen display, with libOSMesa loaded by dlopen.
#include "receiver/display/osmesa_display.h"

#include <GL/osmesa.h>
#include <dlfcn.h>

#include <stdexcept>
#include <vector>

#include "receiver/display/gl_blit.h"

namespace headcast {

struct OsMesaDisplay::Impl {
  void* library = nullptr;
  OSMesaContext (*create)(GLenum, GLint, GLint, GLint, OSMesaContext) = nullptr;
  GLboolean (*make_current)(OSMesaContext, void*, GLenum, GLsizei, GLsizei) = nullptr;
  void (*destroy)(OSMesaContext) = nullptr;
  OSMESAproc (*get_proc)(const char*) = nullptr;
  OSMesaContext context = nullptr;
  std::vector<uint8_t> buffer;
  GlFunctions functions;
  std::unique_ptr<GlBlitter> blitter;
  ~Impl() {
    blitter.reset();
    if (context && destroy) destroy(context);
    if (library) dlclose(library);
  }
};

OsMesaDisplay::OsMesaDisplay(int width, int height) : impl_(std::make_unique<Impl>()), width_(width), height_(height) {
  for (const char* name : {"libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so"}) {
    impl_->library = dlopen(name, RTLD_NOW | RTLD_LOCAL);
    if (impl_->library) break;
  }
  if (!impl_->library) throw std::runtime_error("offscreen display: cannot load libOSMesa (install libosmesa6)");
  auto sym = [&](auto& fn, const char* name) {
    fn = reinterpret_cast<std::remove_reference_t<decltype(fn)>>(dlsym(impl_->library, name));
    if (!fn) throw std::runtime_error(std::string("offscreen display: libOSMesa lacks ") + name);
  };
  sym(impl_->create, "OSMesaCreateContextExt");
  sym(impl_->make_current, "OSMesaMakeCurrent");
  sym(impl_->destroy, "OSMesaDestroyContext");
  sym(impl_->get_proc, "OSMesaGetProcAddress");
}

OsMesaDisplay::~OsMesaDisplay() = default;

void OsMesaDisplay::Open(int width, int height) {
  width_ = width;
  height_ = height;
  impl_->context = impl_->create(OSMESA_RGBA, 0, 0, 0, nullptr);
  if (!impl_->context) throw std::runtime_error("offscreen display: OSMesaCreateContextExt failed");
  impl_->buffer.assign(static_cast<size_t>(width) * height * 4, 0);
  if (!impl_->make_current(impl_->context, impl_->buffer.data(), GL_UNSIGNED_BYTE, width, height))
    throw std::runtime_error("offscreen display: OSMesaMakeCurrent failed");
  impl_->functions.Load([this](const char* name) { return reinterpret_cast<void*>(impl_->get_proc(name)); });
  impl_->blitter = std::make_unique<GlBlitter>(impl_->functions);
}

bool OsMesaDisplay::Show(const cv::Mat& image, const DisplayOverlay&) {
  if (!impl_->context) Open(width_ > 0 ? width_ : image.cols, height_ > 0 ? height_ : image.rows);
  impl_->make_current(impl_->context, impl_->buffer.data(), GL_UNSIGNED_BYTE, width_, height_);
  impl_->blitter->Draw(image, width_, height_);
  last_ = impl_->blitter->Read(width_, height_, GL_FRONT);
  return true;
}

}  // namespace headcast
