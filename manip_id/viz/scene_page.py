"""An offline meshcat scene and its standalone page.

:class:`RecordingWindow` stands in for meshcat's viewer window: it keeps the scene tree
(as meshcat's server keeps it for a newly connected browser) instead of sending it, and
gives back the packed commands in replay order. :func:`page_html` is the standalone page
that replays them (three.js from the meshcat package embedded, or loaded beside it).
"""

from __future__ import annotations

import html as html_lib
from dataclasses import dataclass, field
from pathlib import Path

import meshcat
import umsgpack
from meshcat.servers.tree import SceneTree, find_node, walk

from ..errors import ManipIdError


class RecordingWindow:
    """Stands in for meshcat's ViewerWindow: keeps the scene tree instead of sending it.

    The tree holds, per path, the last object, its properties, its transform and
    the animation, as meshcat's server does for a newly connected browser.
    """

    def __init__(self):
        self.tree = SceneTree()

    def send(self, command) -> None:
        data = command.lower()
        packed = umsgpack.packb(data)
        kind = data["type"]
        path = [p for p in data.get("path", "").split("/") if p]
        if kind == "set_object":
            node = find_node(self.tree, path)
            node.object = packed
            node.properties = []
        elif kind == "set_transform":
            find_node(self.tree, path).transform = packed
        elif kind == "set_property":
            node = find_node(self.tree, path)
            node.properties = [
                p for p in node.properties if umsgpack.unpackb(p)["property"] != data["property"]
            ]
            node.properties.append(packed)
        elif kind == "set_animation":
            find_node(self.tree, path).animation = packed
        elif kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()

    def commands(self) -> list[bytes]:
        """Packed commands in replay order (objects, properties, transforms, animation)."""
        out: list[bytes] = []
        animations: list[bytes] = []
        for node in walk(self.tree):
            if node.object is not None:
                out.append(node.object)
            out.extend(node.properties)
            if node.transform is not None:
                out.append(node.transform)
            if node.animation is not None:
                animations.append(node.animation)
        return out + animations

    def get_image(self):  # pragma: no cover - Pinocchio only checks that it exists
        raise ManipIdError("an offline scene has no image; export it with write_html")


class OfflineVisualizer(meshcat.Visualizer):
    """A meshcat.Visualizer bound to a :class:`RecordingWindow` (no server)."""

    def get_image(self, *args):  # pragma: no cover
        return self.window.get_image()


def viewer_js() -> str:
    """meshcat's viewer (three.js included), as the meshcat package ships it."""
    return (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text()


_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ margin: 0; }}
#wrap {{ display: flex; width: 100vw; height: 100vh; }}
#meshcat-pane {{ flex: 1 1 auto; min-width: 0; height: 100vh; overflow: hidden;
  position: relative; }}
#legend {{ flex: 0 0 min(270px, 32vw); box-sizing: border-box; height: 100vh; overflow: auto;
  background: #f6f6f4; border-right: 1px solid #bbb; font: 12px sans-serif; padding: 6px 8px;
  line-height: 1.5; }}
#legend summary {{ cursor: pointer; font-weight: bold; }}
#legend .sw {{ display: inline-block; width: 11px; height: 11px; border: 1px solid #444;
  vertical-align: middle; margin: 0 3px; box-sizing: border-box; }}
#legend .sw.wire {{ background: transparent !important; border: 2px dashed; }}
#legend .note {{ color: #a33; }}
#legend details details summary {{ font-weight: normal; color: #a33; }}
</style></head>
<body>
<div id="wrap">
<aside id="legend"><details open><summary>Legend</summary>
{legend}
</details></aside>
<div id="meshcat-pane"></div>
</div>
{viewer}
{data}
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
for (const b64 of commands) {{
  const raw = atob(b64);
  const bytes = new Uint8Array(raw.length);
  for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
  viewer.handle_command_bytearray(bytes);
}}
(function () {{
  const m = /[#&]t=([0-9.eE+-]+)/.exec(window.location.hash);
  if (m && viewer.animator && viewer.animator.actions.length) {{
    const t = parseFloat(m[1]);
    viewer.animator.pause();
    viewer.animator.seek(t);
    viewer.animator.display_progress(t);
  }}
}})();
</script>
</body>
</html>
"""


def page_html(title: str, legend: str, viewer: str, data: str) -> str:
    """The standalone page: ``title`` and ``legend`` HTML, the viewer and data scripts."""
    return _PAGE.format(title=title, legend=legend, viewer=viewer, data=data)


@dataclass
class LegendSection:
    """A section of the page's legend: a bold title, lines of HTML, short notes (text)
    folded in a closed ``<details>``."""

    title: str
    lines: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # short, shown folded

    def html(self) -> str:
        parts = [f"<b>{self.title}</b>", *self.lines]
        if self.notes:
            items = "<br>".join(
                f'<span class="note">{html_lib.escape(n)}</span>' for n in self.notes
            )
            count = f"{len(self.notes)} note{'s' if len(self.notes) > 1 else ''}"
            parts.append(f"<details><summary>{count}</summary>{items}</details>")
        return "<br>".join(parts)
