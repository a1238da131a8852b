"""The user-facing tools: a trained run as a predictor (`predictor`, `jaxmotion.load`), K futures of a clip
from a file (`predict_file`, `predict_markers`), retargeting futures to BVH (`retarget`, `joint_maps`),
pictures and animations (`viz`, `animate`), the interactive viewer (`viewer`), a trained model on a folder
of clips (`evaluate_folder`) and body fitting to C3D recordings (`fit_c3d`)."""
