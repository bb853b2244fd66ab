"""The interactive viewer (``radiance-probes view``): a GLFW window with Dear ImGui panels over
the same Renderer the CLI uses. Only launch.py's callers import glfw and imgui, lazily."""
