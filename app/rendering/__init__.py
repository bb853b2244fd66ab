"""The renderers (docs/design.md). Importing the package gives the GPU layer its shader files
(shader_files.py: the one place that reads glsl/)."""
from radiance_probes.rendering.shader_files import install as _install_shader_files

_install_shader_files()
