"""pyGLFW bound to imgui-bundle's own libglfw. Importing imgui_bundle first points pyGLFW at the
library its C++ backend is linked with (PYGLFW_LIBRARY), so the window we create and the one
ImGui's GLFW backend reads are in one GLFW; import glfw from here, never directly."""
from imgui_bundle import imgui  # noqa: F401  (must precede the glfw import)

import glfw  # noqa: E402

__all__ = ["glfw"]
