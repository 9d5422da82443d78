"""The explorer (`robotadapt explore`, docs/explorer.md): a local web app on Bokeh's server where every change of a law,
a gain or a setting re-runs the closed loop and redraws the run's figures and metrics.

Modules, lowest first: :mod:`.view` (the page's state and its URL), :mod:`.catalogue` (what a view runs: scenarios, the
lineup, the controls, the runs and their cache), :mod:`.runner` (latest-wins runs on a worker thread), :mod:`.curves`
(a run as the page's data: decimated curves, metrics rows), :mod:`.panels` (the Bokeh figures), :mod:`.app` (the page),
:mod:`.download` (the zip of a run), :mod:`.server` (the loopback server and its Host/Origin guard).
"""
