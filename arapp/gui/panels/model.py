"""Model panel: the library with thumbnails, open a file, placement on the anchor, display mode,
and the control-point editor for NURBS models."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QSize, Qt, Signal
from PySide6.QtGui import QIcon, QImage, QPixmap
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QListView,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from arapp.exchange.meshes import file_filter
from arapp.gui.panels.compact_spin import CompactSpin
from arapp.app.session import OCCLUSION_CHOICES
from arapp.engine.pipeline import MODES
from arapp.geometry.placement import Placement

# the mesh suffixes come from the one table of formats (arapp.exchange.meshes.FORMATS)
MODEL_FILTER = f"Models (*.json {file_filter()});;NURBS models (*.json);;Meshes ({file_filter()})"
THUMB = 72


def _spin(lo: float, hi: float, step: float, decimals: int, suffix: str = "",
          sample: str | None = None, suffix_room: str = "") -> QDoubleSpinBox:
    """A spin box; with `sample` (a typical value's text) sized for that value, not the range's ends."""
    s = QDoubleSpinBox() if sample is None else CompactSpin(sample, suffix_room)
    s.setRange(lo, hi)
    s.setSingleStep(step)
    s.setDecimals(decimals)
    s.setKeyboardTracking(False)  # typing "120" applies once, not as 1, 12, 120
    if suffix:
        s.setSuffix(suffix)
    return s


class ModelPanel(QWidget):
    """Widgets only; the main window loads models and talks to the pipeline.

    Signals: model_chosen(path), placement_changed(arapp.geometry.placement.Placement),
    mode_changed(str), occlusion_changed(str), point_selected(surface, i, j),
    point_edited(surface, i, j, (x, y, z), weight), print_requested().
    """

    model_chosen = Signal(str)
    open_requested = Signal()
    placement_changed = Signal(object)
    mode_changed = Signal(str)
    occlusion_changed = Signal(str)
    point_selected = Signal(int, int, int)
    point_edited = Signal(int, int, int, tuple, float)
    print_requested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        self._build_library(lay)
        self._build_placement(lay)
        self._build_control_point(lay)
        self._quiet = False
        self._surfaces = []
        self._tilt = (0.0, 0.0)
        self.set_placement(Placement())
        self.set_model_loaded(False)

    def _build_library(self, lay) -> None:
        """The models/ library list, Open and Print buttons and the loaded model's name."""
        self.library = QListWidget()
        # a list, thumbnail left and the whole name right: an icon grid cut long names off
        self.library.setViewMode(QListView.ViewMode.ListMode)
        self.library.setIconSize(QSize(THUMB // 2, THUMB // 2))
        self.library.setResizeMode(QListView.ResizeMode.Adjust)
        self.library.setMovement(QListView.Movement.Static)
        self.library.setWordWrap(True)
        self.library.setMinimumHeight(3 * (THUMB // 2 + 6) + 8)
        self.library.itemActivated.connect(self._activated)
        self.library.itemClicked.connect(self._activated)
        lay.addWidget(QLabel("Library (models/)"))
        lay.addWidget(self.library, 1)
        row = QHBoxLayout()
        self.open_button = QPushButton("Open model...")
        self.open_button.clicked.connect(self.open_requested)
        self.print_button = QPushButton("Print... (P)")
        self.print_button.clicked.connect(self.print_requested)
        row.addWidget(self.open_button)
        row.addWidget(self.print_button)
        lay.addLayout(row)
        self.current = QLabel("No model")
        self.current.setWordWrap(True)
        lay.addWidget(self.current)

    def _build_placement(self, lay) -> None:
        """Size, offset, rotation, display mode and occlusion of the model on the anchor."""
        place = QGroupBox("Placement on the anchor")
        self.place_box = place
        pf = QFormLayout(place)
        self.size = _spin(1.0, 1000.0, 5.0, 1, " mm")
        self.offset = [_spin(-1000.0, 1000.0, 1.0, 1, " mm") for _ in range(3)]
        self.rotation = _spin(-360.0, 360.0, 5.0, 1, " deg")
        pf.addRow("Size", self.size)
        off_row = QHBoxLayout()
        for s in self.offset:
            off_row.addWidget(s)
        pf.addRow("Offset x y z", off_row)
        pf.addRow("Rotation", self.rotation)
        self.mode = QComboBox()
        self.mode.addItems(MODES)
        self.mode.currentTextChanged.connect(self.mode_changed)
        pf.addRow("Display", self.mode)
        self.occlusion = QComboBox()
        self.occlusion.addItems(OCCLUSION_CHOICES)
        self.occlusion.setToolTip("Hide the model behind real things: depth (a depth camera's or a recording's "
                                  "depth), plane (below the anchor's table top), off; auto: depth when the "
                                  "source gives depth, else off")
        self.occlusion.currentTextChanged.connect(self.occlusion_changed)
        pf.addRow("Occlusion", self.occlusion)
        for s in (self.size, self.rotation, *self.offset):
            s.valueChanged.connect(self._placement_edited)
        lay.addWidget(place)

    def _build_control_point(self, lay) -> None:
        """The NURBS control point picked (surface, u, v) with its weight and position."""
        edit = QGroupBox("Control point (NURBS)")
        ef = QFormLayout(edit)
        self.surface_index = QSpinBox()
        self.u_index = QSpinBox()
        self.v_index = QSpinBox()
        sel = QHBoxLayout()
        for label, s in (("surface", self.surface_index), ("u", self.u_index), ("v", self.v_index)):
            sel.addWidget(QLabel(label))
            sel.addWidget(s)
            s.valueChanged.connect(self._selection_changed)
        ef.addRow(sel)
        self.weight = _spin(-100.0, 100.0, 0.1, 3)
        # a control point's coordinates are a few hundred model units at most in practice; the range only
        # keeps a typed value from being cut off; room for a unit such as " mm", set when a model loads
        self.position = [_spin(-1e6, 1e6, 0.1, 3, sample="-000.000", suffix_room=" mm") for _ in range(3)]
        ef.addRow("Weight", self.weight)
        pos_row = QHBoxLayout()
        for s in self.position:
            pos_row.addWidget(s)
        self.position_label = QLabel("Position")
        ef.addRow(self.position_label, pos_row)
        for s in (self.weight, *self.position):
            s.valueChanged.connect(self._point_edited)
        self.edit_box = edit
        edit.setEnabled(False)
        lay.addWidget(edit)

    def set_model_loaded(self, loaded: bool) -> None:
        """Placement and Print act only on a loaded model."""
        self.place_box.setEnabled(loaded)
        self.print_button.setEnabled(loaded)

    def mark_loaded(self, path: str | None) -> None:
        """Highlight the library entry of the loaded model (bold, selected); the others plain."""
        for i in range(self.library.count()):
            item = self.library.item(i)
            mine = path is not None and Path(item.data(Qt.ItemDataRole.UserRole)).resolve() == Path(path).resolve()
            font = item.font()
            font.setBold(mine)
            item.setFont(font)
            item.setSelected(mine)
            if mine:
                self.library.setCurrentItem(item)

    # -- library -----------------------------------------------------------------------
    def set_library(self, paths: list[Path]) -> None:
        self.library.clear()
        for p in paths:
            item = QListWidgetItem(p.stem)
            item.setData(Qt.ItemDataRole.UserRole, str(p))
            item.setToolTip(str(p))
            self.library.addItem(item)

    def set_thumbnail(self, path: str, bgr) -> None:
        """bgr: (h, w, 3) uint8 picture for the library entry of `path`."""
        h, w = bgr.shape[:2]
        img = QImage(bgr.data, w, h, bgr.strides[0], QImage.Format.Format_BGR888).copy()
        for i in range(self.library.count()):
            item = self.library.item(i)
            if item.data(Qt.ItemDataRole.UserRole) == path:
                item.setIcon(QIcon(QPixmap.fromImage(img)))

    def _activated(self, item: QListWidgetItem) -> None:
        self.model_chosen.emit(item.data(Qt.ItemDataRole.UserRole))

    # -- current model -------------------------------------------------------------------
    def set_model(self, model, path: str, placement) -> None:
        """Show the loaded model's name, its placement and (for NURBS) its control points."""
        name = getattr(model, "name", None) or Path(path).stem
        surfaces = list(getattr(model, "surfaces", None) or [])
        self.current.setText(f"<b>{name}</b> &nbsp; {Path(path).name}" + (
            f", {len(surfaces)} NURBS surface{'s' if len(surfaces) != 1 else ''}" if surfaces else ", mesh"))
        self.set_placement(placement)
        # control points are in the model file's own unit (placement is in mm); each field shows it, so the
        # label stays short and the panel keeps its width
        units = str(getattr(model, "units", "") or "model units")
        for box in self.position:
            box.setSuffix(f" {units}")
        self.set_model_loaded(True)
        self.mark_loaded(path)
        self._surfaces = surfaces
        self.edit_box.setEnabled(bool(surfaces))
        self._quiet = True
        self.surface_index.setRange(0, max(0, len(surfaces) - 1))
        self.surface_index.setValue(0)
        self._quiet = False
        # the fields show the first point, but none is ringed in the view until the user picks one (a ring
        # on a corner of every new model was drawn, and paid for, on every frame)
        self._show_selection(picked=False)

    def set_surfaces(self, surfaces: list) -> None:
        """The edited surfaces (same shapes), so the fields show the values in force."""
        self._surfaces = list(surfaces)
        self._show_selection(picked=False)  # undo / redo: the fields show the restored point

    def set_placement(self, p: Placement) -> None:
        """Show a placement (size_mm, offset mm, rotation_deg: the turn about z is edited here)."""
        self._quiet = True
        self.size.setValue(p.size_mm)
        for s, v in zip(self.offset, p.offset):
            s.setValue(v)
        self._tilt = tuple(float(a) for a in p.rotation_deg[:2])  # turns about x and y stay the model's
        self.rotation.setValue(float(p.rotation_deg[2]))
        self._quiet = False

    def placement(self) -> Placement:
        return Placement(self.size.value(), tuple(s.value() for s in self.offset),
                         (*self._tilt, self.rotation.value()))

    def _placement_edited(self) -> None:
        if not self._quiet:
            self.placement_changed.emit(self.placement())

    def selected(self) -> tuple[int, int, int]:
        return self.surface_index.value(), self.u_index.value(), self.v_index.value()

    def _selection_changed(self) -> None:
        """The user picked a control point (a surface / u / v field changed): the fields show it, the view rings it."""
        self._show_selection(picked=True)

    def _show_selection(self, picked: bool) -> None:
        """The fields show the selected control point; `picked` (the user chose it): the view rings it."""
        if self._quiet or not self._surfaces:
            return
        k = min(self.surface_index.value(), len(self._surfaces) - 1)
        s = self._surfaces[k]
        n_u, n_v = s.control_points.shape[:2]
        self._quiet = True
        self.u_index.setRange(0, n_u - 1)
        self.v_index.setRange(0, n_v - 1)
        i, j = self.u_index.value(), self.v_index.value()
        self.weight.setValue(float(s.weights[i, j]))
        for box, v in zip(self.position, s.control_points[i, j]):
            box.setValue(float(v))
        self._quiet = False
        if picked:
            self.point_selected.emit(k, i, j)

    def _point_edited(self) -> None:
        if self._quiet or not self._surfaces:
            return
        k, i, j = self.selected()
        xyz = tuple(float(b.value()) for b in self.position)
        self.point_edited.emit(k, i, j, xyz, float(self.weight.value()))
