"""The plug-in tabs of the control panel, in the order the tab bar shows them after the Monte Carlo tab
(`tab_plugin`: a new tab is its panel's module, its controller's module and one entry here)."""

from __future__ import annotations

from .controllers.diagnose import DiagnoseController
from .controllers.model_check import ModelCheckController
from .diagnosis_panel import DiagnosePanel
from .model_check_panel import ModelCheckPanel
from .tab_plugin import TabSpec

TABS: tuple[TabSpec, ...] = (
    TabSpec("diagnose", "Diagnose", "STETHOSCOPE", DiagnosePanel, DiagnoseController),
    TabSpec("model_check", "Model", "CHECKLIST", ModelCheckPanel, ModelCheckController),
)
