"""The anchor offer bar: "Found a 4x3 DICT_4X4_50 board (ids 0-11): use it? Marker size: [40] mm  [Use it]
[Not now]", shown under the view when anchor discovery (arapp.engine.discovery) found anchors in a source whose
configured ones give no pose; and the why line added to the lost-marker hint.

Non-modal: the video keeps playing. Use it calls Session.use_offer with the size entered (the anchors are
remembered for that source and the source reopened with them); Not now calls Session.dismiss_offer.
"""

from __future__ import annotations

from PySide6.QtWidgets import QDoubleSpinBox, QFrame, QHBoxLayout, QLabel, QPushButton


class AnchorOfferBar(QFrame):
    """The offer strip. `show_offer(offer)` (an arapp.engine.discovery.offer_dict) fills and shows it; the
    buttons answer through `use(size_mm)` / `dismiss()` callables given at construction."""

    def __init__(self, use, dismiss, parent=None):
        super().__init__(parent)
        self._use, self._dismiss = use, dismiss
        self.setObjectName("anchor_offer")
        self.setStyleSheet("#anchor_offer { background: #dff0d8; color: #1e4620; }")
        lay = QHBoxLayout(self)
        lay.setContentsMargins(8, 3, 8, 3)
        self.label = QLabel("")
        self.label.setWordWrap(True)
        self.size_label = QLabel("Marker size:")
        self.size = QDoubleSpinBox()
        self.size.setRange(1.0, 2000.0)
        self.size.setDecimals(1)
        self.size.setSuffix(" mm")
        self.size.setToolTip("The side of one printed marker (a QR code: its side), measured on the print")
        self.use_button = QPushButton("Use it")
        self.not_now_button = QPushButton("Not now")
        self.use_button.clicked.connect(self._used)
        self.not_now_button.clicked.connect(self._dismissed)
        lay.addWidget(self.label, 1)
        for w in (self.size_label, self.size, self.use_button, self.not_now_button):
            lay.addWidget(w)
        self.offer: dict | None = None
        self.hide()

    def show_offer(self, offer: dict) -> None:
        if not offer.get("summary") or not offer.get("block"):
            return   # only a why line: the hint tells it
        self.offer = offer
        summary = str(offer["summary"])
        self.label.setText(f"Found {summary}: use it?")
        self.size_label.setText("Code size:" if offer.get("block", {}).get("kind") == "qr" else "Marker size:")
        self.size.setValue(float(offer.get("size_mm") or 40.0))
        self.show()

    def clear(self) -> None:
        self.offer = None
        self.hide()

    def _used(self) -> None:
        self.hide()
        self._use(self.size.value())

    def _dismissed(self) -> None:
        self.hide()
        self._dismiss()


class AnchorOffer:
    """The bar under the window's view and the hint's why line, bound to the window's session."""

    def __init__(self, window):
        self.w = window
        s = window.session
        self.bar = AnchorOfferBar(s.use_offer, s.dismiss_offer, window)
        layout = window.centralWidget().layout()
        layout.insertWidget(layout.indexOf(window.view) + 1, self.bar)
        s.events.anchor_offer.connect(self.bar.show_offer)
        s.events.source_opening.connect(lambda *_: self.bar.clear())
        s.events.frame.connect(self._frame)   # after the first-hour hint has worded its text

    def _frame(self, shown) -> None:
        hint = getattr(getattr(self.w, "first_hour", None), "hint", None)
        offer = self.w.session.anchor_offer
        if hint is None or hint.isHidden() or not offer or not offer.get("why"):
            return
        why = str(offer["why"])
        why = why[:1].upper() + why[1:]
        if why not in hint.text():
            hint.setText(f"{hint.text()}\n{why}")
            hint.adjustSize()


def install(window) -> AnchorOffer:
    """Put the anchor offer into `window` (a MainWindow); returns it (the window keeps it as `anchor_offer`)."""
    return AnchorOffer(window)
