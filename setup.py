"""The one installed package, `radiance_probes`, is the `app/` folder (the design card's top level
keeps `app`, `glsl` and `assets` side by side). Its subpackages are discovered, never listed; the
shaders and assets travel inside it as package data (app/paths.py finds them in either place).
Everything else about the project is in pyproject.toml."""
from setuptools import find_namespace_packages, find_packages, setup

PACKAGE = "radiance_probes"
DATA = {"glsl": "glsl", "assets": "assets"}        # package data folders: name inside -> checkout
# files beside a subpackage's modules: the napari plugin's npe2 manifest (the napari.manifest entry
# point names it)
FILES = {f"{PACKAGE}.napari_plugin": ["napari.yaml"]}

data_packages = [f"{PACKAGE}.{name}" + (f".{sub}" if sub else "")
                 for name, folder in DATA.items() for sub in ["", *find_namespace_packages(folder)]]
setup(
    packages=[PACKAGE, *(f"{PACKAGE}.{p}" for p in find_packages("app")), *data_packages],
    package_dir={PACKAGE: "app", **{f"{PACKAGE}.{name}": folder for name, folder in DATA.items()}},
    package_data={**{p: ["*"] for p in data_packages}, **FILES},
    exclude_package_data={"": ["__pycache__/*", "*.pyc"]},
)
