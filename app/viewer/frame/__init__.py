"""A frame of the viewer: the progressive session, the frames' pacing, the Denoise view and refine's judgements spread over frames, each frame's named parts."""
