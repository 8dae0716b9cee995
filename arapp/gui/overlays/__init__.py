"""What is painted over the view: detected markers (`marker_marks`) and the 3D orbit view of the model
(`orbit_view`) when there is nothing to put it on."""
