"""The Parameters panel: every stage's tunable values, built from its Schema.

Sliders and spin boxes show units and ranges; the help text is the tooltip.
Each edit is validated by the schema before it leaves the panel as
``changed(stage, {name: value})``; the window sends node stages to the site
(applied live) and applies local stages (``view``) itself. Presets are
config files written and read by ``optrack.params.save_config`` and
``load_config``; they hold the nodes' stages only.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QScrollArea,
    QSlider,
    QSpinBox,
    QToolBox,
    QVBoxLayout,
    QWidget,
)

from optrack.params import Param, ParamError, Params, Schema, load_config, save_config

# A slider has at most this many positions; finer steps are typed in the spin box.
MAX_SLIDER_POSITIONS = 10000
MAX_DECIMALS = 6


def decimals_for(param: Param) -> int:
    """Fewest decimals that show the step, bounds and default exactly (at most 6)."""
    numbers = [v for v in (param.step, param.min, param.max, param.default) if v is not None]
    for decimals in range(MAX_DECIMALS + 1):
        if all(abs(round(float(v), decimals) - float(v)) < 1e-12 for v in numbers):
            return decimals
    return MAX_DECIMALS


# Words of parameter and stage names an operator reads in capitals.
ACRONYMS = frozenset(
    "bvh cpu csv fps gui hog icp id ip ir json osc pnp rgb rms tls ttl udp ukf uri url".split()
)
# Unit spellings written the way an operator reads them.
UNIT_SIGNS = (("^-1", "⁻¹"), ("^2", "²"), ("^3", "³"), ("^4", "⁴"))


def unit_text(text: str) -> str:
    """``text`` with exponents written as superscripts (m^2/s^4 -> m²/s⁴)."""
    for written, shown in UNIT_SIGNS:
        text = text.replace(written, shown)
    return text


def title_for(name: str) -> str:
    """A stage or parameter name in words: ``ukf_alpha`` -> "UKF alpha"."""
    words = [w.upper() if w in ACRONYMS else w for w in name.split("_") if w]
    if words and not words[0].isupper():
        words[0] = words[0].capitalize()
    return " ".join(words)


def tooltip_for(stage: str, param: Param, value: Any = None) -> str:
    """The help text, the accepted range and the default; the value in use when it is
    not the default (a site may start a stage with other values than the schema's)."""
    now = "" if value is None or value == param.default else f"; in use now: {value}"
    return unit_text(
        f"{stage}.{param.name}: {param.help}\n"
        f"Accepts {param.describe_range()}; default {param.default}{now}."
    )


class ParamEditor(QWidget):
    """The control of one parameter; ``edited(value)`` when the operator changes it."""

    edited = Signal(object)

    def __init__(self, stage: str, param: Param, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.param = param
        self.slider: QSlider | None = None
        self.spin: QSpinBox | QDoubleSpinBox | None = None
        self.check: QCheckBox | None = None
        self.combo: QComboBox | None = None
        self.line: QLineEdit | None = None
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        kind = param.kind
        if kind is bool:
            self.check = QCheckBox()
            self.check.toggled.connect(lambda on: self.edited.emit(bool(on)))
            layout.addWidget(self.check)
            layout.addStretch(1)
        elif param.choices:
            self.combo = QComboBox()
            self.combo.addItems(list(param.choices))
            self.combo.currentTextChanged.connect(self.edited.emit)
            layout.addWidget(self.combo, 1)
        elif kind is str:
            self.line = QLineEdit()
            self.line.editingFinished.connect(lambda: self.edited.emit(self.line.text()))
            layout.addWidget(self.line, 1)
        else:
            self._build_number(kind, layout)
        self.stage = stage
        self.label: QLabel | None = None  # the form's name of this control (same tooltip)
        self.set_value(param.default)

    def _build_number(self, kind: type, layout: QHBoxLayout) -> None:
        param = self.param
        if kind is int:
            spin: QSpinBox | QDoubleSpinBox = QSpinBox()
            spin.setRange(
                int(param.min) if param.min is not None else -(2**31) + 1,
                int(param.max) if param.max is not None else 2**31 - 1,
            )
            spin.setSingleStep(int(param.step or 1))
        else:
            spin = QDoubleSpinBox()
            spin.setDecimals(decimals_for(param))
            spin.setRange(
                param.min if param.min is not None else -1e12,
                param.max if param.max is not None else 1e12,
            )
            spin.setSingleStep(param.step or 10.0 ** -spin.decimals())
        spin.setKeyboardTracking(False)  # one edit when the operator presses Enter
        spin.setAccelerated(True)
        if param.unit:
            spin.setSuffix(f" {unit_text(param.unit)}")
        # Wide enough for the longest value and its unit: a narrow dock never cuts it off.
        spin.setMinimumWidth(max(110, spin.sizeHint().width()))
        self.spin = spin
        if param.min is not None and param.max is not None and param.max > param.min:
            step = param.step or (param.max - param.min) / 1000
            positions = round((param.max - param.min) / step)
            if positions > MAX_SLIDER_POSITIONS:
                positions, step = (
                    MAX_SLIDER_POSITIONS,
                    (param.max - param.min) / MAX_SLIDER_POSITIONS,
                )
            self._slider_step = step
            self.slider = QSlider(Qt.Orientation.Horizontal)
            self.slider.setRange(0, positions)
            self.slider.setMinimumWidth(90)
            self.slider.valueChanged.connect(self._slider_moved)
            self.slider.sliderReleased.connect(lambda: self.edited.emit(self.value()))
            layout.addWidget(self.slider, 1)
        spin.valueChanged.connect(self._spin_changed)
        layout.addWidget(spin)

    def _slider_value(self, position: int) -> int | float:
        param = self.param
        value = min(max(param.min + position * self._slider_step, param.min), param.max)
        if param.kind is int:
            return int(round(value))
        return round(value, self.spin.decimals())

    def _slider_moved(self, position: int) -> None:
        self.spin.blockSignals(True)
        self.spin.setValue(self._slider_value(position))
        self.spin.blockSignals(False)
        if not self.slider.isSliderDown():  # a click, a key or a wheel: one edit
            self.edited.emit(self.value())

    def _spin_changed(self, value: float) -> None:
        self._place_slider(value)
        self.edited.emit(self.value())

    def _place_slider(self, value: float) -> None:
        if self.slider is None:
            return
        self.slider.blockSignals(True)
        self.slider.setValue(round((value - self.param.min) / self._slider_step))
        self.slider.blockSignals(False)

    def busy(self) -> bool:
        """Is the operator using this control now (dragging, typing)?"""
        if self.slider is not None and self.slider.isSliderDown():
            return True
        return any(
            widget is not None and widget.hasFocus()
            for widget in (self.spin, self.line, self.combo)
        )

    def value(self) -> Any:
        if self.check is not None:
            return self.check.isChecked()
        if self.combo is not None:
            return self.combo.currentText()
        if self.line is not None:
            return self.line.text()
        return int(self.spin.value()) if self.param.kind is int else float(self.spin.value())

    def set_value(self, value: Any) -> None:
        """Show a value without emitting ``edited``."""
        for widget in (self.check, self.combo, self.line, self.spin):
            if widget is not None:
                widget.blockSignals(True)
        try:
            if self.check is not None:
                self.check.setChecked(bool(value))
            elif self.combo is not None:
                self.combo.setCurrentText(str(value))
            elif self.line is not None:
                self.line.setText(str(value))
            else:
                self.spin.setValue(value)
                self._place_slider(value)
        finally:
            for widget in (self.check, self.combo, self.line, self.spin):
                if widget is not None:
                    widget.blockSignals(False)
        self.setToolTip(tooltip_for(self.stage, self.param, self.value()))
        if self.label is not None:
            self.label.setToolTip(self.toolTip())


class ParametersPanel(QWidget):
    """One page per stage; presets of the node stages; ``changed(stage, values)``."""

    changed = Signal(str, object)  # {name: value}, passed as it is
    problem = Signal(str)  # a sentence for the Log dock

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.pages = QToolBox()
        self.load_button = QPushButton("Load preset…")
        self.save_button = QPushButton("Save preset…")
        self.defaults_button = QPushButton("Defaults")
        self.defaults_button.setToolTip("Set every parameter of the open page to its default.")
        self.message = QLabel("")
        self.message.setWordWrap(True)
        buttons = QHBoxLayout()
        buttons.addWidget(self.load_button)
        buttons.addWidget(self.save_button)
        buttons.addStretch(1)
        buttons.addWidget(self.defaults_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(buttons)
        layout.addWidget(self.message)
        layout.addWidget(self.pages, 1)
        self.schemas: dict[str, Schema] = {}
        self.values: dict[str, Params] = {}
        self.editors: dict[str, dict[str, ParamEditor]] = {}
        self.local_stages: set[str] = set()
        self.load_button.clicked.connect(self._ask_load)
        self.save_button.clicked.connect(self._ask_save)
        self.defaults_button.clicked.connect(self._defaults_of_open_page)

    # ------------------------------------------------------------- building
    def set_schemas(
        self,
        schemas: Mapping[str, Schema],
        values: Mapping[str, Mapping[str, Any]] | None = None,
        local: bool = False,
    ) -> None:
        """Show these stages (replacing pages of the same name) with their current values.

        ``local`` stages change the window only and are left out of presets."""
        for stage, schema in schemas.items():
            self._remove_page(stage)
            self.schemas[stage] = schema
            self.values[stage] = schema.create((values or {}).get(stage))
            if local:
                self.local_stages.add(stage)
            else:
                self.local_stages.discard(stage)
            self._add_page(stage, schema)

    def _remove_page(self, stage: str) -> None:
        if stage not in self.schemas:
            return
        for index in range(self.pages.count()):
            if self.pages.widget(index).objectName() == stage:
                widget = self.pages.widget(index)
                self.pages.removeItem(index)
                widget.deleteLater()
                break
        del self.schemas[stage], self.values[stage], self.editors[stage]

    def _add_page(self, stage: str, schema: Schema) -> None:
        body = QWidget()
        form = QFormLayout(body)
        form.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        # A dock is narrow: each name above its control, so nothing is cut off.
        form.setRowWrapPolicy(QFormLayout.RowWrapPolicy.WrapAllRows)
        if schema.help:
            intro = QLabel(schema.help)
            intro.setWordWrap(True)
            form.addRow(intro)
        editors = {}
        for param in schema:
            editor = ParamEditor(stage, param)
            editor.set_value(self.values[stage][param.name])
            editor.edited.connect(
                lambda value, stage=stage, name=param.name: self.edit(stage, name, value)
            )
            unit = f" ({unit_text(param.unit)})" if param.unit else ""
            editor.label = QLabel(f"<b>{title_for(param.name)}</b>{unit}")
            editor.label.setToolTip(editor.toolTip())
            form.addRow(editor.label, editor)
            editors[param.name] = editor
        self.editors[stage] = editors
        scroll = QScrollArea()
        scroll.setObjectName(stage)
        scroll.setWidgetResizable(True)
        scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        scroll.setWidget(body)
        title = title_for(stage)
        index = self.pages.addItem(
            scroll, title if stage not in self.local_stages else f"{title} (this window)"
        )
        self.pages.setItemToolTip(index, f"Section '{stage}' of a config file or preset.")

    # -------------------------------------------------------------- editing
    def edit(self, stage: str, name: str, value: Any) -> bool:
        """The operator set ``stage.name``: validate, remember, emit ``changed``."""
        try:
            changed = self.values[stage].update({name: value})
        except ParamError as error:
            self._say(str(error))
            self.editors[stage][name].set_value(self.values[stage][name])
            return False
        self.message.setText("")
        if changed:
            self.changed.emit(stage, changed)
        return True

    def set_values(self, stage: str, values: Mapping[str, Any]) -> None:
        """Values reported by the nodes: shown, not sent back. A control the operator is
        using keeps what the operator is doing."""
        if stage not in self.schemas:
            return
        editors = self.editors[stage]
        known = {
            k: v for k, v in values.items() if k in self.schemas[stage] and not editors[k].busy()
        }
        try:
            self.values[stage].update(known)
        except ParamError as error:
            self._say(f"A node reported a value this window refuses: {error}")
            return
        for name in known:
            editors[name].set_value(self.values[stage][name])

    def _apply(self, stage: str, values: Mapping[str, Any]) -> None:
        changed = self.values[stage].update(values)
        for name in changed:
            self.editors[stage][name].set_value(self.values[stage][name])
        if changed:
            self.changed.emit(stage, changed)

    def _defaults_of_open_page(self) -> None:
        page = self.pages.currentWidget()
        if page is not None:
            stage = page.objectName()
            self._apply(stage, self.schemas[stage].defaults())

    def _say(self, sentence: str) -> None:
        self.message.setText(sentence)
        self.problem.emit(sentence)

    # -------------------------------------------------------------- presets
    def node_stages(self) -> dict[str, Schema]:
        return {s: schema for s, schema in self.schemas.items() if s not in self.local_stages}

    def save_preset(self, path: str | os.PathLike[str]) -> bool:
        stages = self.node_stages()
        try:
            save_config(path, {stage: self.values[stage] for stage in stages}, registry=stages)
        except (ParamError, OSError) as error:
            self._say(f"The preset was not saved to {path}: {error}")
            return False
        self.message.setText(f"Saved the preset to {path}.")
        return True

    def load_preset(self, path: str | os.PathLike[str]) -> bool:
        """Read a preset and apply it (stages it leaves out go back to their defaults)."""
        try:
            loaded = load_config(path, registry=self.node_stages())
        except ParamError as error:
            self._say(str(error))
            return False
        for stage, params in loaded.items():
            self._apply(stage, params.as_dict())
        self.message.setText(f"Loaded the preset {path}.")
        return True

    def _ask_load(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self, "Load a parameter preset", "", "YAML (*.yaml *.yml)"
        )
        if path:
            self.load_preset(path)

    def _ask_save(self) -> None:
        path, _ = QFileDialog.getSaveFileName(
            self, "Save the parameters as a preset", "", "YAML (*.yaml *.yml)"
        )
        if path:
            if not os.path.splitext(path)[1]:
                path += ".yaml"
            self.save_preset(path)
