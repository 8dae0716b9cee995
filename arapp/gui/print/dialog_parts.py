"""Two parts of the print dialog (arapp.gui.print.dialog.PrintDialog mixes them in): whether the part fits
the bed before slicing (with Scale to fit), and the toolpath preview on the real bed with its layer slider.
They use the dialog's widgets and its print session (`self.session`)."""

from __future__ import annotations

from dataclasses import replace

from arapp.app.bed_fit import bed_fit
from arapp.printing.printers import resolve_profile


class BedFitPart:
    """Compare the printable solid with the printer's bed before slicing; offer Scale to fit."""

    def check_fit(self, *_args) -> None:
        """Compare the solid's real size with the chosen printer's bed (with the skirt); offer scale to fit."""
        solid = self.session.solid
        if solid is None:
            return
        try:
            fit = bed_fit(solid.extents, resolve_profile(self.profile_key()), self.slice_settings())
        except (ValueError, OSError):
            fit = None  # an unreadable profile or setting: slicing reports it
        self._show_fit(fit)

    def _show_fit(self, fit) -> None:
        self._fit = fit
        too_big = fit is not None and not fit.fits
        self.fit_label.setText(fit.text + " Slicing needs it smaller." if too_big else "")
        self.fit_label.setVisible(too_big)
        self.fit_button.setVisible(too_big)
        if too_big:
            self.fit_button.setText(f"Scale to fit ({self.session.placement.size_mm * fit.scale:.1f} mm)")
        if hasattr(self, "slice_button") and not self.session.slicing:
            self.slice_button.setEnabled(not too_big)

    def scale_to_fit(self) -> None:
        """Shrink the part (its placement, so the AR view shows the same) until it fits the bed."""
        fit, ps = self._fit, self.session
        if fit is None or fit.fits or not fit.scale > 0:
            return
        ps.placement = replace(ps.placement, size_mm=ps.placement.size_mm * fit.scale)
        name = getattr(ps.model, "name", "model")
        self.model_label.setText(f"<b>{name}</b>, placed {ps.placement.size_mm:.1f} mm at its largest")
        self.solid_label.setText("Preparing the printable solid...")
        self._show_fit(None)
        self.placement_requested.emit(ps.placement)
        ps.solid = None
        ps.make_solid()



class BedPreviewPart:
    """The sliced toolpaths on the printer bed in the AR view: the layer slider and its label."""

    def _setup_preview(self) -> None:
        """After slicing: the layer slider spans the layers (its last position: all layers), warnings shown."""
        ps = self.session
        n = ps.summary.layers if ps.summary is not None else 0
        self._set_slider(n, maximum=max(0, n))  # 0..n-1: one layer; n: all layers
        warnings = [w for w in ([ps.summary.warning(ps.profile.bed)] if ps.summary is not None else []) if w]
        self.preview_warning.setText("\n".join(warnings))
        self.preview_warning.setVisible(bool(warnings))
        self.preview_check.setEnabled(ps.preview_possible)
        self.layer_slider.setEnabled(ps.preview_possible and not ps.printing)
        ps.preview_layer = self.preview_layer
        self._update_layer_label()

    def _set_slider(self, value: int, maximum: int | None = None) -> None:
        """Move the layer slider without it asking for a preview."""
        self.layer_slider.blockSignals(True)
        if maximum is not None:
            self.layer_slider.setRange(0, maximum)
        self.layer_slider.setValue(min(value, self.layer_slider.maximum()))
        self.layer_slider.blockSignals(False)

    @property
    def preview_layer(self) -> int | None:
        """The slider's layer (0-based), None for all layers."""
        v = self.layer_slider.value()
        return None if v >= self.layer_slider.maximum() else v

    def _update_layer_label(self) -> None:
        ps, s = self.session, self.session.summary
        if s is None or not s.layers:
            self.layer_label.setText("slice first")
        elif ps.current_layer >= 0 and ps.printing:
            k = min(ps.current_layer, s.layers - 1)
            self.layer_label.setText(f"printing layer {k + 1} / {s.layers}, z {s.z[k]:.2f} mm")
        elif self.preview_layer is None:
            self.layer_label.setText(f"all {s.layers} layers")
        else:
            k = self.preview_layer
            self.layer_label.setText(f"layer {k + 1} / {s.layers}, z {s.z[k]:.2f} mm")

    def preview_toggled(self, on: bool) -> None:
        self.session.set_preview(on, self.preview_layer)

    def layer_changed(self, _value: int) -> None:
        self._update_layer_label()
        self.session.preview_layer = self.preview_layer
        if self.preview_check.isChecked():
            self.session.emit_preview()

    def preview_shown(self, info: dict) -> None:
        """The live view drew the preview `info` (arapp.engine.toolpaths): say where it stands, warn when it
        leaves the build area."""
        if info.get("placed_text"):
            self.placement_note.setText(f"The toolpaths are drawn {info['placed_text']}.")
            self.placement_note.setVisible(True)
        elif not info.get("layers"):
            self.placement_note.setVisible(False)
        if info.get("outside") and not self.preview_warning.isVisible():
            self.preview_warning.setText("Toolpaths leave the build area (drawn red on the bed).")
            self.preview_warning.setVisible(True)
