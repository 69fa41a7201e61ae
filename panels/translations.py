"""The add-on's words for Blender's translation system (bpy.app.translations): a language's table maps
(context, English text) to its text. Labels built in code use the English text with str.format's {} as
the key, so one entry serves every value. French is the first table; another language is another dict."""
import bpy

# Operator labels are looked up in Blender's "Operator" context, everything else in the default "*".
_FRENCH_OPERATORS = {
    "Run All": "Tout lancer", "Convert": "Convertir", "Estimate Light": "Estimer la lumière",
    "Adapt": "Adapter", "Compose": "Composer", "Bake Asset": "Cuire l'asset", "Import Asset": "Importer l'asset",
    "Pick Placement": "Choisir l'emplacement", "Pick Sun": "Choisir le soleil", "Match Camera": "Caler la caméra",
    "Write Prompt": "Écrire le prompt", "Open Folder": "Ouvrir le dossier", "Copy Details": "Copier les détails",
    "Cancel": "Annuler", "Resume": "Reprendre", "Apply Run": "Appliquer l'essai", "Delete Run": "Supprimer l'essai",
}
_FRENCH = {
    "Asset": "Asset", "Scene": "Scène", "Style": "Style", "Quality": "Qualité", "Run": "Lancer",
    "Results": "Résultats", "Photo": "Photo", "Placement": "Emplacement", "Size": "Taille", "Turn": "Rotation",
    "Camera": "Caméra", "Sun": "Soleil", "Prompt": "Prompt", "Preset": "Préréglage", "Output": "Sortie",
    "Material": "Matériau", "World": "Monde", "Original": "Original", "Details": "Détails",
    "Bake Asset…": "Cuire l'asset…", "Modules missing": "Modules manquants", "Unsaved file": "Fichier non enregistré",
    "No UV map": "Pas de carte UV", "Material not readable": "Matériau illisible",
    "{} objects, one asset": "{} objets, un seul asset", "'{}' is flat": "« {} » est plat",
    "{} inputs dropped": "{} entrées ignorées", "Camera: {}": "Caméra : {}", "Runs of '{}'": "Essais de « {} »",
    "(the example asset on a {})": "(l'asset d'exemple sur un {})", "{:.0f} s": "{:.0f} s", "{:.0f} min": "{:.0f} min",
    "{:.1f} h": "{:.1f} h", "{:.1f} days": "{:.1f} jours", "{}: about {:.0f} s": "{} : environ {:.0f} s",
    "{}: under 1 s": "{} : moins d'une seconde", "{}: not measured yet": "{} : pas encore mesuré",
    "adapt: not measured yet": "adaptation : pas encore mesurée",
    "adapt: about {} on a CPU, {} on an H200 (SD2 size)": "adaptation : environ {} sur un CPU, {} sur une H200 "
                                                          "(taille SD2)",
    "{}: stage {} of {}": "{} : étape {} sur {}", "about {} left": "encore environ {}",
    "finished": "terminé", "cancelled": "annulé", "failed": "échoué", "cancelled, resumable": "annulé, reprenable",
}

translations_dict = {"fr_FR": {**{("*", k): v for k, v in _FRENCH.items()},
                               **{("Operator", k): v for k, v in _FRENCH_OPERATORS.items()}}}


def register() -> None:
    bpy.app.translations.register(__package__, translations_dict)


def unregister() -> None:
    bpy.app.translations.unregister(__package__)
