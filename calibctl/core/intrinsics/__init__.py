"""One camera's lens: the intrinsic solve (OpenCV pinhole models, calibctl's fisheye LM), the model table
and solution type, covariance and sigmas, held-out validation, model selection (``--model auto``),
outlier rejection, the numeric lint checks and the model-misfit test, projection-uncertainty maps.
May import ``core.board`` and the shared ``core.blas_threads`` / ``core.gate``; never capture, extrinsics,
check or synth.
"""
