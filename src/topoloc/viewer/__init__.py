"""The interactive viewer: one self-contained offline HTML file per drive (Leaflet through folium, inlined).

:mod:`~topoloc.viewer.page` writes the file from a :class:`~topoloc.viewer.page.ViewerData` (the road graph as a
vector layer, the true track, every localizer's answers over time, the belief at stored moments, marks, images);
:mod:`~topoloc.viewer.belief` computes the metric filter's belief along a drive; the stages ``view_drive`` and
``view_repeat`` (and ``topoloc localize --html``) fill the data from the pipeline's outputs. The behaviour
(slider, playback, layers, chart) is ``assets/viewer.js``.
"""
