"""What the front ends share: the scene from command-line options, output checks and files, images on disk, the colour bar and the progress bar."""
