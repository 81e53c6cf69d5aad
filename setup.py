"""Build of kinecal's optional compiled model kernel (the project is in pyproject.toml).

The extension is optional: without a C compiler the build goes on without it, and the
model runs its numpy code (kinecal.models._kernel). The build then says so in a banner
and leaves the reason in ``kinecal/models/_ckernel_build.txt``, which ``kinecal
--version`` and the one-time warning of kinecal.models._kernel quote.

The kernel uses only the stable ABI of Python 3.11 (``Py_LIMITED_API``), so the wheel is
tagged ``cp311-abi3`` and serves every CPython from 3.11 on.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

NOTE = Path("kinecal", "models", "_ckernel_build.txt")


class BuildExt(build_ext):
    """GCC, Clang and MSVC: no fused multiply-adds, so that every build rounds alike
    (ARM64 compilers contract a * b + c by default, MSVC before 17.0 under its default
    /fp:precise). GCC and Clang optimise with -O3 whatever the Python was built with
    (Debian's and Ubuntu's own Pythons pass -O2: the kernel ran 1.3x slower, 0.95
    against 0.71 ms for the full model's Jacobian of 2000 poses, with the same numbers).
    A failed build of the kernel is reported in a banner and a note installed with the
    package."""

    def build_extensions(self) -> None:
        kind = self.compiler.compiler_type
        for ext in self.extensions:
            if kind == "unix":
                ext.extra_compile_args = [
                    *ext.extra_compile_args,
                    "-O3",
                    "-ffp-contract=off",
                ]
            elif kind == "msvc":
                ext.extra_compile_args = [*ext.extra_compile_args, *self._msvc_args()]
        super().build_extensions()

    def _msvc_args(self) -> list[str]:
        """MSVC: no contractions under every version's default /fp:precise.

        Microsoft's documentation of ``#pragma fp_contract``
        (https://learn.microsoft.com/cpp/preprocessor/fp-contract): "When you use the
        default compiler options, fp_contract is off ... This behavior is new in Visual
        Studio 2022 version 17.0. In previous compiler versions, fp_contract defaulted
        to on." The /fp:contract option exists from 17.0 only (older compilers refuse
        it), so the portable switch is the pragma itself, put at the top of the kernel
        by a header forced in with /FI, keeping /fp:precise (not /fp:strict, whose
        floating-point environment access costs speed).
        """
        header = Path(self.build_temp, "kinecal_fp_contract_off.h")
        header.parent.mkdir(parents=True, exist_ok=True)
        header.write_text("#pragma fp_contract(off)\n", encoding="ascii")
        return ["/fp:precise", f"/FI{header.resolve()}"]

    def _note(self) -> Path:
        root = Path("src") if self.inplace else Path(self.build_lib)
        return root / NOTE

    def build_extension(self, ext: Extension) -> None:
        note = self._note()
        try:
            super().build_extension(ext)
        except Exception as exc:  # no compiler, no Python headers, a compile error
            reason = " ".join(str(exc).split()) or type(exc).__name__
            # A compiler that ran and failed: its name and status, not its whole line.
            ran = re.match(
                r"Command '\['([^']*)'.*(returned non-zero exit status \d+)", reason
            )
            if ran:
                reason = f"the C compiler {ran[1]} {ran[2]}"
            note.parent.mkdir(parents=True, exist_ok=True)
            note.write_text(f"{reason}\n", encoding="utf-8")
            bar = "*" * 78
            print(
                f"\n{bar}\nWARNING: kinecal's compiled model kernel was not built:\n"
                f"  {reason}\nkinecal works without it (numpy code, 2-4x slower). "
                "Install a C compiler\n(gcc, clang or MSVC) and reinstall kinecal to "
                f"build it.\n{bar}\n",
                file=sys.stderr,
                flush=True,
            )
            if not ext.optional:
                raise
        else:
            note.unlink(missing_ok=True)


setup(
    ext_modules=[
        Extension(
            "kinecal.models._ckernel",
            ["src/kinecal/models/_ckernel.c"],
            define_macros=[("Py_LIMITED_API", "0x030B0000")],
            py_limited_api=True,
            optional=True,
        )
    ],
    cmdclass={"build_ext": BuildExt},
    options={"bdist_wheel": {"py_limited_api": "cp311"}},
)
