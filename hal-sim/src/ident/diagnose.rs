//! Model discovery (`piezo diagnose`): base CBW fit, candidate causes, residual signatures, iterative extension.
