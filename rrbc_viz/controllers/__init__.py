"""The app's controllers, one per feature, each over the shared `context.AppContext` and implementing one interface of
`actions`: `evaluate` (drags, settings, display, layers), `present` (an evaluation onto every view), `views` (camera,
selection, slice, lesson), `plan`, `montecarlo`, `vec`, `authoring` and `files`; and the plug-in tabs' controllers
(`tab_plugin.TabController`, listed in `tabs.TABS`): `diagnose` and `model_check`."""
