"""Place recognition under appearance change and topometric teach-and-repeat localization (Cai & Wan).

* :mod:`~topoloc.place.images`: place images rendered by :mod:`topoloc.render` at the network's input size:
  training routes away from the evaluation route, the teach drive and the repeat drives;
* :mod:`~topoloc.place.render_places`: the ``render_places`` stage;
* :mod:`~topoloc.place.pairs`: positive / negative image pairs by metric distance (the 2 m rule);
* :mod:`~topoloc.place.network`: the compact ResNet-style backbone, the siamese head, the Lightning module;
* :mod:`~topoloc.place.train_retrieval`: the ``train_retrieval`` stage;
* :mod:`~topoloc.place.odometry`: path integration of noisy odometry;
* :mod:`~topoloc.place.topometric_map`: vertices and navigation commands;
  :mod:`~topoloc.place.build_topometric_map`: the ``build_topometric_map`` stage;
* :mod:`~topoloc.place.topometric_localization`: the paper's loop: window search, odometry fallback and global
  relocalization; scorers;
* :mod:`~topoloc.place.markov`: Markov localization, a Bayes filter over the vertices (beyond the paper);
* :mod:`~topoloc.place.localize_repeat`: the ``localize_repeat`` stage and its tables;
* :mod:`~topoloc.place.plot`: figures.
"""
