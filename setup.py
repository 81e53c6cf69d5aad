"""Build of kinecal's optional compiled model kernel (the project is in pyproject.toml).

The extension is optional: without a C compiler the build goes on without it, and the
model runs its numpy code (kinecal.models._kernel).
"""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class BuildExt(build_ext):
    """GCC and Clang: no fused multiply-adds, so that every build rounds alike (ARM64
    compilers contract a * b + c by default)."""

    def build_extensions(self) -> None:
        if self.compiler.compiler_type == "unix":
            for ext in self.extensions:
                ext.extra_compile_args = [*ext.extra_compile_args, "-ffp-contract=off"]
        super().build_extensions()


setup(
    ext_modules=[
        Extension(
            "kinecal.models._ckernel",
            ["src/kinecal/models/_ckernel.c"],
            optional=True,
        )
    ],
    cmdclass={"build_ext": BuildExt},
)
