"""The app's controllers, one per feature, each over the shared `context.AppContext` and implementing one interface of
`actions`: `evaluate` (drags, settings, display, layers), `present` (an evaluation onto every view), `views` (camera,
selection, slice, lesson), `plan`, `diagnose`, `montecarlo`, `vec`, `authoring` and `files`."""
