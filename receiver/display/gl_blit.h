// Draws an image as a full-viewport textured quad with legacy OpenGL, through
// function pointers so that the same code serves a GLFW context (libGL) and an
// OSMesa context (libOSMesa) in one process without symbol clashes.
#pragma once

#include <GL/gl.h>

#include <functional>
#include <opencv2/core.hpp>

namespace headcast {

struct GlFunctions {
  void (*Viewport)(GLint, GLint, GLsizei, GLsizei) = nullptr;
  void (*ClearColor)(GLfloat, GLfloat, GLfloat, GLfloat) = nullptr;
  void (*Clear)(GLbitfield) = nullptr;
  void (*GenTextures)(GLsizei, GLuint*) = nullptr;
  void (*DeleteTextures)(GLsizei, const GLuint*) = nullptr;
  void (*BindTexture)(GLenum, GLuint) = nullptr;
  void (*TexParameteri)(GLenum, GLenum, GLint) = nullptr;
  void (*TexImage2D)(GLenum, GLint, GLint, GLsizei, GLsizei, GLint, GLenum, GLenum, const void*) = nullptr;
  void (*PixelStorei)(GLenum, GLint) = nullptr;
  void (*Enable)(GLenum) = nullptr;
  void (*Disable)(GLenum) = nullptr;
  void (*Begin)(GLenum) = nullptr;
  void (*End)() = nullptr;
  void (*TexCoord2f)(GLfloat, GLfloat) = nullptr;
  void (*Vertex2f)(GLfloat, GLfloat) = nullptr;
  void (*MatrixMode)(GLenum) = nullptr;
  void (*LoadIdentity)() = nullptr;
  void (*ReadPixels)(GLint, GLint, GLsizei, GLsizei, GLenum, GLenum, void*) = nullptr;
  void (*Finish)() = nullptr;
  void (*ReadBuffer)(GLenum) = nullptr;

  // Looks every function up with `lookup`; throws naming the first one missing.
  void Load(const std::function<void*(const char*)>& lookup);
};

class GlBlitter {
 public:
  explicit GlBlitter(const GlFunctions& gl) : gl_(gl) {}
  ~GlBlitter();
  // Uploads `image_bgr` and draws it scaled to a viewport of `width` x `height`.
  void Draw(const cv::Mat& image_bgr, int width, int height);
  // The current framebuffer as BGR, top row first.
  cv::Mat Read(int width, int height, GLenum buffer) const;

 private:
  const GlFunctions& gl_;
  GLuint texture_ = 0;
};

}  // namespace headcast
