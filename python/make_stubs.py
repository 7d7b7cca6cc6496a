"""Writes hanzo/fusion/_fusion.pyi under PACKAGE_DIR: mypy's stubgen reads the built module's
pybind11 signatures; their numpy spellings ("numpy.ndarray[numpy.float64[3,1]]") become
numpy.typing.ArrayLike for arguments (lists convert too) and NDArray for results, and static
methods (which stubgen writes as untyped instance methods) get their signatures."""
import pathlib
import re
import sys

from mypy import stubgen

package_dir = pathlib.Path(sys.argv[1])
stubgen.main(["--quiet", "-m", "hanzo.fusion._fusion", "-o", str(package_dir)])
stub = package_dir / "hanzo" / "fusion" / "_fusion.pyi"
sys.path.insert(0, str(package_dir))
from hanzo.fusion import _fusion  # noqa: E402

static_methods = {}  # "    def name(self, *args, **kwargs) -> Any: ..." line -> its typed replacement
for cls in vars(_fusion).values():
    if isinstance(cls, type):
        for name, attribute in vars(cls).items():
            if isinstance(attribute, staticmethod):
                signature = attribute.__func__.__doc__.splitlines()[0].replace("hanzo.fusion._fusion.", "")
                static_methods[(cls.__name__, name)] = f"    @staticmethod\n    def {signature}: ..."
array = re.compile(r"numpy\.ndarray\[numpy\.(\w+)(\[[^\]]*\])?(,\s*flags\.\w+)*\]")
lines = []
current_class = None
for line in stub.read_text().splitlines():
    if line.strip() == "import flags":
        continue
    if line.startswith("class "):
        current_class = line[len("class "):].split("(")[0].split(":")[0]
    method = re.match(r"    def (\w+)\(self, \*args, \*\*kwargs\) -> Any: \.\.\.$", line)
    if method and (current_class, method.group(1)) in static_methods:
        line = static_methods[(current_class, method.group(1))]
    head, arrow, result = line.partition(") -> ")
    head = array.sub("numpy.typing.ArrayLike", head)
    result = array.sub(lambda m: f"numpy.typing.NDArray[numpy.{m.group(1)}]", result)
    lines.append(head + arrow + result)
text = "\n".join(lines) + "\n"
if "__version__" not in text:
    text += "\n__version__: str\n"
text = text.replace("import numpy\n", "import numpy\nimport numpy.typing\n", 1)
stub.write_text(text)
