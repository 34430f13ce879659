// Textured-quad drawing with legacy OpenGL through function pointers.
#include "receiver/display/gl_blit.h"

#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>

namespace headcast {

void GlFunctions::Load(const std::function<void*(const char*)>& lookup) {
  auto get = [&](auto& fn, const char* name) {
    fn = reinterpret_cast<std::remove_reference_t<decltype(fn)>>(lookup(name));
    if (!fn) throw std::runtime_error(std::string("OpenGL function ") + name + " is not available");
  };
  get(Viewport, "glViewport");
  get(ClearColor, "glClearColor");
  get(Clear, "glClear");
  get(GenTextures, "glGenTextures");
  get(DeleteTextures, "glDeleteTextures");
  get(BindTexture, "glBindTexture");
  get(TexParameteri, "glTexParameteri");
  get(TexImage2D, "glTexImage2D");
  get(PixelStorei, "glPixelStorei");
  get(Enable, "glEnable");
  get(Disable, "glDisable");
  get(Begin, "glBegin");
  get(End, "glEnd");
  get(TexCoord2f, "glTexCoord2f");
  get(Vertex2f, "glVertex2f");
  get(MatrixMode, "glMatrixMode");
  get(LoadIdentity, "glLoadIdentity");
  get(ReadPixels, "glReadPixels");
  get(Finish, "glFinish");
  get(ReadBuffer, "glReadBuffer");
}

GlBlitter::~GlBlitter() {
  if (texture_ && gl_.DeleteTextures) gl_.DeleteTextures(1, &texture_);
}

void GlBlitter::Draw(const cv::Mat& image, int width, int height) {
  if (image.type() != CV_8UC3) throw std::invalid_argument("GlBlitter: expects CV_8UC3 BGR");
  const cv::Mat contiguous = image.isContinuous() ? image : image.clone();
  if (!texture_) {
    gl_.GenTextures(1, &texture_);
    gl_.BindTexture(GL_TEXTURE_2D, texture_);
    // Nearest at 1:1 keeps pixels exact; linear when the window is resized.
    gl_.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    gl_.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  }
  gl_.BindTexture(GL_TEXTURE_2D, texture_);
  const bool same_size = width == image.cols && height == image.rows;
  gl_.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, same_size ? GL_NEAREST : GL_LINEAR);
  gl_.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, same_size ? GL_NEAREST : GL_LINEAR);
  gl_.PixelStorei(GL_UNPACK_ALIGNMENT, 1);
  gl_.TexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, contiguous.cols, contiguous.rows, 0, GL_BGR, GL_UNSIGNED_BYTE,
                 contiguous.data);
  gl_.Viewport(0, 0, width, height);
  gl_.ClearColor(0, 0, 0, 1);
  gl_.Clear(GL_COLOR_BUFFER_BIT);
  gl_.MatrixMode(GL_PROJECTION);
  gl_.LoadIdentity();
  gl_.MatrixMode(GL_MODELVIEW);
  gl_.LoadIdentity();
  gl_.Enable(GL_TEXTURE_2D);
  // Image row 0 is the top; GL's v = 0 is the first uploaded row.
  gl_.Begin(GL_QUADS);
  gl_.TexCoord2f(0, 1);
  gl_.Vertex2f(-1, -1);
  gl_.TexCoord2f(1, 1);
  gl_.Vertex2f(1, -1);
  gl_.TexCoord2f(1, 0);
  gl_.Vertex2f(1, 1);
  gl_.TexCoord2f(0, 0);
  gl_.Vertex2f(-1, 1);
  gl_.End();
  gl_.Disable(GL_TEXTURE_2D);
  gl_.Finish();
}

cv::Mat GlBlitter::Read(int width, int height, GLenum buffer) const {
  cv::Mat flipped(height, width, CV_8UC3);
  gl_.ReadBuffer(buffer);
  gl_.PixelStorei(GL_PACK_ALIGNMENT, 1);
  gl_.ReadPixels(0, 0, width, height, GL_BGR, GL_UNSIGNED_BYTE, flipped.data);
  cv::Mat out;
  cv::flip(flipped, out, 0);  // GL's first row is the bottom
  return out;
}

}  // namespace headcast
