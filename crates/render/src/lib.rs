//! volmorph-render: Cameras, image buffers, colour maps and PNG output shared by volmorph's renderers.
